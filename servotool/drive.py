"""Drive operations over a link: coalesced reads, validated and verified writes, Fn triggers, roles."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from itertools import pairwise

from servotool.errors import DeviceError, ModbusException, UsageError, VerifyError
from servotool.link.ports import ControlLine, Link
from servotool.model.codec import (
    fields_json,
    format_value,
    json_text,
    json_value,
    parse_value,
    raw_to_eng,
    raw_to_words,
    split_field,
    words_to_raw,
)
from servotool.model.lookup import enum_value
from servotool.model.profile import Entry, Profile


@dataclass(frozen=True)
class Reading:
    """One entry's value as read from the drive."""

    entry: Entry
    raw: int

    @property
    def eng(self) -> float | int:
        return raw_to_eng(self.entry, self.raw)

    @property
    def text(self) -> str:
        return format_value(self.entry, self.raw)

    @property
    def changed(self) -> bool:
        return self.entry.default is not None and self.raw != self.entry.default

    def as_json(self) -> dict[str, object]:
        e = self.entry
        out: dict[str, object] = {
            "code": e.code,
            "name": e.name,
            "value": json_value(e, self.raw),
            "raw": self.raw,
            "unit": e.unit,
        }
        if (text := json_text(e, self.raw)) is not None:
            out["text"] = text
        if (fields := fields_json(e, self.raw)) is not None:
            out["fields"] = fields
            meanings = {f: m for f, v in fields.items() if (m := e.field_enums.get(f.upper(), {}).get(v))}
            if meanings:
                out["meanings"] = meanings
        if self.raw in e.enum:
            out["meaning"] = e.enum[self.raw]
        if e.default is not None:
            out["default"] = json_value(e, e.default)
            if (text := json_text(e, e.default)) is not None:
                out["default_text"] = text
            out["changed"] = self.changed
        return out


@dataclass(frozen=True)
class WriteResult:
    """Outcome of one verified parameter write."""

    entry: Entry
    old: int | None
    new: int

    @property
    def note(self) -> str:
        return {
            "servo_off": "takes effect with the servo off",
            "power_cycle": "takes effect after a power cycle",
            "unknown": "the manual does not say when it takes effect",
        }.get(self.entry.effect, "")


def _prefixed(exc: DeviceError, prefix: str) -> DeviceError:
    """Name the entry in a link error, keeping its type (and exit code)."""
    exc.args = (f"{prefix}: {exc.args[0] if exc.args else exc}",)
    return exc


ILLEGAL_ADDRESS = 2  # the Modbus exception of an address the drive does not have


class NotOnDrive(ModbusException):
    """Entries the profile lists but the drive lacks: it answers exception 02 (illegal data address) for them."""

    def __init__(self, entries: list[Entry]) -> None:
        DeviceError.__init__(
            self,
            f"{', '.join(e.code for e in entries)}: not on this drive (it answers Modbus "
            f"exception 02, illegal data address, for "
            f"{'its address' if len(entries) == 1 else 'their addresses'})",
        )
        self.code, self.entries = ILLEGAL_ADDRESS, entries


_READABLE: dict[int, tuple[list[Entry], frozenset[int]]] = {}


def readable_addresses(profile: Profile) -> frozenset[int]:
    """Every address of the profile's readable entries (kept per profile: a backup coalesces 80 times)."""
    cached = _READABLE.get(id(profile))
    if cached is None or cached[0] is not profile.entries:
        cached = (profile.entries, frozenset(a for e in profile.entries if e.readable for a in e.addresses))
        _READABLE[id(profile)] = cached
    return cached[1]


def coalesce_reads(
    profile: Profile, entries: Iterable[Entry], holes: frozenset[int] = frozenset()
) -> list[tuple[int, int, list[Entry]]]:
    """Group entries into as few FC03 requests as the profile allows: (address, count, entries).

    A request may span a gap only when every address in the gap belongs to a readable entry, since a real
    drive answers exception 02 for unmapped addresses, and none is a hole (an address the drive turned out to lack).
    """
    readable = readable_addresses(profile)
    wanted = sorted({e.code: e for e in entries}.values(), key=lambda e: e.address)
    plans: list[tuple[int, int, list[Entry]]] = []
    limit = profile.limits.max_read
    for e in wanted:
        if plans:
            start, count, group = plans[-1]
            end = start + count
            gap_ok = all(a in readable and a not in holes for a in range(end, e.address))
            new_count = e.address + e.words - start
            if e.address >= end and gap_ok and new_count <= limit:
                plans[-1] = (start, new_count, [*group, e])
                continue
            if e.address < end:  # overlapping or repeated: already covered
                if e.address + e.words <= end:
                    plans[-1] = (start, count, [*group, e])
                    continue
        plans.append((e.address, e.words, [e]))
    return plans


def _names(group: list[Entry]) -> str:
    return ", ".join(e.code for e in group[:4]) + (" ..." if len(group) > 4 else "")


class Drive:
    """One drive (unit) on a link, described by a profile."""

    def __init__(self, link: Link, profile: Profile, unit: int, *, port: str = "") -> None:
        """port names the bus for the host's journal and write lock (ops/journal); "" for in-process links."""
        self.link = link
        # The user acknowledged host motion without a dead-man on this drive (--no-dead-man): see motion/deadman.
        self.dead_man_waived = False
        # A hardware dead-man (--heartbeat): the adapter's control line a watchdog relay watches, toggled at each
        # keep-alive beat (motion/keepalive), and the relay's time in seconds.
        self.heartbeat_line: ControlLine | None = None
        self.heartbeat_timeout_s: float | None = None
        self.profile = profile
        self.unit = unit
        self.port = port
        self.missing: dict[str, Entry] = {}  # entries the drive answered exception 02 for, this run, by code
        readable = [e for e in profile.entries if e.readable]
        self._starting = {e.address: e for e in readable}  # readable entries by first and by past-last address
        self._ending = {e.address + e.words: e for e in readable}

    # ----- reading -------------------------------------------------------------------------------------------
    def read_entries(
        self, entries: Iterable[Entry], progress: Callable[[int], None] | None = None, *, partial: bool = False
    ) -> list[Reading]:
        """Read entries in coalesced requests; results in the order asked.

        An entry the drive lacks (exception 02) is found by splitting the request that met it, remembered in
        `missing` (never asked for again) and raises NotOnDrive; with partial=True it is left out instead."""
        entries = list(entries)
        for e in entries:
            if not e.readable:
                raise UsageError(f"{e.code} ({e.name}) is write-only and cannot be read")
        values: dict[str, int] = {}
        if partial or not any(e.code in self.missing for e in entries):
            for start, count, group in coalesce_reads(
                self.profile, [e for e in entries if e.code not in self.missing], self._holes()
            ):
                self._read_block(start, count, group, values)
                if progress:
                    progress(len(group))
        lacking = [e for e in entries if e.code in self.missing]
        if lacking and not partial:
            raise NotOnDrive(list({e.code: e for e in lacking}.values()))
        return [Reading(e, values[e.code]) for e in entries if e.code in values]

    def _holes(self) -> frozenset[int]:
        return frozenset(a for e in self.missing.values() for a in e.addresses)

    def _read_block(self, start: int, count: int, group: list[Entry], values: dict[str, int]) -> None:
        """Read one coalesced block into values; on exception 02, split it in two and read each half, down to the
        single entry the drive lacks."""
        try:
            words = self.link.read(self.unit, start, count, spare=self._spare(start, count))
        except ModbusException as exc:
            if exc.code != ILLEGAL_ADDRESS:
                raise _prefixed(exc, f"reading {_names(group)}") from None
            if len(group) == 1:
                self.missing[group[0].code] = group[0]
                return
            half = len(group) // 2
            for part in (group[:half], group[half:]):
                for s, c, g in coalesce_reads(self.profile, part, self._holes()):
                    self._read_block(s, c, g, values)
            return
        except DeviceError as exc:
            raise _prefixed(exc, f"reading {_names(group)}") from None
        for e in group:
            off = e.address - start
            values[e.code] = words_to_raw(e, words[off : off + e.words])

    def _spare(self, start: int, count: int) -> tuple[int, int]:
        """Registers of the readable entries just before and just after a block (none the drive lacks), within the
        profile's read limit: the link may read them too, so that this read's reply differs in length from the
        replies around it (link/exchange.py)."""
        room = self.profile.limits.max_read - count
        spare = []
        for e in (self._starting.get(start + count), self._ending.get(start)):
            words = e.words if e is not None and e.code not in self.missing and e.words <= room else 0
            spare.append(words)
            room -= words
        return spare[1], spare[0]

    def read(self, *codes: str) -> list[Reading]:
        return self.read_entries(self.profile.entry(c) for c in codes)

    def read_one(self, code_or_role: str) -> Reading:
        return self.read_entries([self.profile.entry(code_or_role)])[0]

    def read_role(self, role: str, feature: str) -> Reading:
        return self.read_entries([self.profile.need_role(role, feature)])[0]

    # ----- writing -------------------------------------------------------------------------------------------
    def parse_assignment(self, text: str, *, raw: bool = False, current: int | None = None) -> tuple[Entry, int]:
        """'CODE=VALUE' or 'CODE.FIELD=VALUE' -> (entry, raw value), validated against the profile (nothing is
        sent). A field assignment changes that field of `current` (else of the default) and keeps the others."""
        if "=" not in text:
            raise UsageError(f"'{text}' is not CODE=VALUE")
        code, _, value = text.partition("=")
        entry, field = split_field(self.profile, code)
        if field is not None:
            if raw:
                raise UsageError(f"{entry.code}.{field}: --raw takes whole register values, not fields")
            named = enum_value(entry.field_enums.get(field.upper(), {}), value)  # 'internal speed' has a space
            value = str(named) if named is not None else value.strip()
            if not value or any(c in value for c in " \t,=_"):
                raise UsageError(f"{entry.code}.{field}: '{value}' is not a single field value")
            value = f"{field}={value}"
        if entry.cls != "Pn":
            raise UsageError(f"{entry.code} ({entry.name}) is a {entry.cls} entry, not a settable parameter")
        if not entry.writable:
            raise UsageError(f"{entry.code} ({entry.name}) is read-only")
        return entry, parse_value(entry, value, raw=raw, current=current)

    def write_raw(self, entry: Entry, raw: int, *, idempotent: bool = True) -> None:
        """Send one entry's value (FC06 for one register, FC16 for several, as the profile allows). idempotent=False
        (an Fn trigger) tells the link never to send it twice."""
        words = raw_to_words(entry, raw)
        once = {} if idempotent else {"idempotent": False}
        try:
            if len(words) == 1:
                self.link.write(self.unit, entry.address, words, multiple=False, **once)
            elif self.profile.limits.write_multiple:
                self.link.write(self.unit, entry.address, words, multiple=True, **once)
            else:
                for i, w in enumerate(words):
                    self.link.write(self.unit, entry.address + i, [w], multiple=False, **once)
        except DeviceError as exc:
            raise _prefixed(exc, f"writing {entry.code}") from None

    def write_verified(self, entry: Entry, raw: int, old: int | None = None) -> WriteResult:
        """Write, read back, and raise VerifyError when the drive holds something else."""
        self.write_raw(entry, raw)
        if entry.readable:
            self._verify({entry.code: (entry, raw)})
        return WriteResult(entry, old, raw)

    def _verify(self, written: dict[str, tuple[Entry, int]]) -> None:
        """Read back what was written; VerifyError for the first entry the drive holds otherwise. A read-back that
        disagrees is read once more before it is believed: a stray reply that slipped through must not make a
        stored value look lost."""
        entries = [e for e, _ in written.values()]
        back = {r.entry.code: r.raw for r in self.read_entries(entries)}
        if differ := [e for e in entries if back[e.code] != written[e.code][1]]:
            back.update((r.entry.code, r.raw) for r in self.read_entries(differ))
        for e, raw in written.values():
            if back[e.code] != raw:
                raise VerifyError(
                    f"{e.code}: wrote {format_value(e, raw)} but the drive reads back {format_value(e, back[e.code])}"
                )

    def write_block_verified(self, items: list[tuple[Entry, int, int | None]]) -> list[WriteResult]:
        """Write entries at adjacent addresses in one FC16 request, then verify each by one coalesced read-back.

        items are (entry, new raw, old raw) in address order; the caller keeps the request within the profile's
        max_write and only uses this when the profile allows FC16.
        """
        first = items[0][0]
        words = [w for e, raw, _ in items for w in raw_to_words(e, raw)]
        for (a, _, _), (b, _, _) in pairwise(items):
            if b.address != a.address + a.words:
                raise ValueError(f"{a.code} and {b.code} are not adjacent")
        try:
            self.link.write(self.unit, first.address, words, multiple=True)
        except DeviceError as exc:
            raise _prefixed(exc, f"writing {', '.join(e.code for e, _, _ in items)}") from None
        if readable := {e.code: (e, raw) for e, raw, _ in items if e.readable}:
            self._verify(readable)
        return [WriteResult(e, old, raw) for e, raw, old in items]

    def trigger(self, role: str, feature: str, value: int | None = None) -> None:
        """Run an Fn function by role (writes its trigger value unless one is given)."""
        entry = self.profile.need_role(role, feature)
        self.write_raw(entry, entry.trigger if value is None else value, idempotent=False)
