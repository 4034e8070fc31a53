"""What a drive's manual says about its alarms beyond their names (profile sections `alarm_causes`, `alarm_log`).

`alarm_causes`: the manual's cause-and-remedy table, per alarm code, with its lines; for an alarm it gives none, the
section's `none` says so (never a cause the manual does not print). `alarm_log`: what the drive keeps of its past
alarms beyond the codes in the alarm_history_N roles: the values recorded with each alarm (speed, bus voltage, ...),
and, on a drive that shows one record at a time, the entry that selects it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from servotool.model.checker import Checker
from servotool.model.profile import Entry

# What a drive records with an alarm, by meaning (the simulator fills them in, the CLI labels them).
CONTEXT_KEYS = ("time", "speed", "bus_voltage", "current", "current_u", "current_v", "inputs", "outputs")
CAUSES_KEYS = {"source", "none", "items"}
ITEM_KEYS = {"codes", "causes", "source", "unverified"}
LOG_KEYS = {"context", "select", "excludes_current", "source", "unverified"}
SELECT_KEYS = {"code", "current", "past"}


@dataclass(frozen=True)
class CauseRemedy:
    cause: str
    remedy: str


@dataclass(frozen=True)
class AlarmNote:
    """The manual's causes and remedies for one or more alarm codes (the manual groups some)."""

    codes: tuple[int, ...]
    causes: tuple[CauseRemedy, ...]
    source: str
    unverified: str = ""


@dataclass(frozen=True)
class AlarmCauses:
    """The manual's cause-and-remedy table: where it is, what it says of alarms it leaves out, its items."""

    source: str
    none: str
    notes: tuple[AlarmNote, ...] = ()

    def of(self, code: int) -> AlarmNote | None:
        return next((n for n in self.notes if code in n.codes), None)


@dataclass(frozen=True)
class RecordSelector:
    """A drive that shows one alarm record at a time: write `current` or 1..past to `code`, then read the record."""

    code: str
    current: int
    past: int


@dataclass(frozen=True)
class AlarmLog:
    """What the drive keeps with its alarm records (context: record code -> meaning -> entry code)."""

    source: str
    context: dict[str, dict[str, str]] = field(default_factory=dict)
    select: RecordSelector | None = None
    excludes_current: bool = False  # the newest past record is the alarm before the current one
    unverified: str = ""

    def context_of(self, code: str) -> dict[str, str]:
        return self.context.get(code.upper(), {})


def parse_alarm_causes(chk: Checker, raw: Any, alarm_codes: set[int]) -> AlarmCauses | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("alarm_causes", "expected a mapping {source, none, items}")
        return None
    chk.known_keys(raw, CAUSES_KEYS, "alarm_causes")
    source = chk.need(raw, "source", "alarm_causes", str)
    none = chk.need(raw, "none", "alarm_causes", str)
    items = raw.get("items") or []
    if not isinstance(items, list):
        chk.bad("alarm_causes.items", "expected a list")
        items = []
    notes: list[AlarmNote] = []
    seen: set[int] = set()
    for i, item in enumerate(items):
        loc = f"alarm_causes.items[{i}]"
        if not isinstance(item, dict):
            chk.bad(loc, "expected a mapping {codes, causes, source}")
            continue
        chk.known_keys(item, ITEM_KEYS, loc)
        codes = item.get("codes")
        if not isinstance(codes, list) or not codes or not all(isinstance(c, int) for c in codes):
            chk.bad(f"{loc}.codes", "expected a non-empty list of alarm codes")
            continue
        for c in codes:
            if c not in alarm_codes:
                chk.bad(f"{loc}.codes", f"{c} is not in the profile's alarms")
            if c in seen:
                chk.bad(f"{loc}.codes", f"alarm {c} has causes twice")
            seen.add(c)
        causes = _causes(chk, item.get("causes"), f"{loc}.causes")
        item_source = chk.need(item, "source", loc, str)
        if causes and item_source:
            notes.append(AlarmNote(tuple(codes), causes, item_source, chk.opt(item, "unverified", loc, str, "")))
    if source is None or none is None:
        return None
    return AlarmCauses(source, none, tuple(notes))


def _causes(chk: Checker, raw: Any, loc: str) -> tuple[CauseRemedy, ...]:
    if not isinstance(raw, list) or not raw:
        chk.bad(loc, "expected a non-empty list of {cause, remedy}")
        return ()
    out: list[CauseRemedy] = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict):
            chk.bad(f"{loc}[{i}]", "expected a mapping {cause, remedy}")
            continue
        chk.known_keys(item, {"cause", "remedy"}, f"{loc}[{i}]")
        cause = chk.need(item, "cause", f"{loc}[{i}]", str)
        remedy = chk.need(item, "remedy", f"{loc}[{i}]", str)
        if cause is not None and remedy is not None:
            out.append(CauseRemedy(cause, remedy))
    return tuple(out)


def parse_alarm_log(chk: Checker, raw: Any, entries: dict[str, Entry]) -> AlarmLog | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("alarm_log", "expected a mapping {context, select, source}")
        return None
    chk.known_keys(raw, LOG_KEYS, "alarm_log")
    source = chk.need(raw, "source", "alarm_log", str)
    context: dict[str, dict[str, str]] = {}
    given = raw.get("context") or {}
    if not isinstance(given, dict):
        chk.bad("alarm_log.context", "expected a mapping of record code -> {meaning: code}")
        given = {}
    for record, values in given.items():
        loc = f"alarm_log.context.{record}"
        entry = entries.get(str(record).upper())
        if entry is None or not entry.readable:
            chk.bad(loc, f"names no readable entry: {record!r}")
            continue
        if not isinstance(values, dict):
            chk.bad(loc, f"expected a mapping of {', '.join(CONTEXT_KEYS)} -> code")
            continue
        chk.known_keys(values, CONTEXT_KEYS, loc)
        found = {k: entries.get(str(v).upper()) for k, v in values.items() if k in CONTEXT_KEYS}
        for k, e in found.items():
            if e is None or not e.readable:
                chk.bad(f"{loc}.{k}", f"names no readable entry: {values[k]!r}")
        context[entry.code.upper()] = {k: e.code for k, e in found.items() if e is not None and e.readable}
    select = _selector(chk, raw.get("select"), entries)
    if source is None:
        return None
    return AlarmLog(
        source=source,
        context=context,
        select=select,
        excludes_current=chk.opt(raw, "excludes_current", "alarm_log", bool, False),
        unverified=chk.opt(raw, "unverified", "alarm_log", str, ""),
    )


def _selector(chk: Checker, raw: Any, entries: dict[str, Entry]) -> RecordSelector | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("alarm_log.select", "expected a mapping {code, current, past}")
        return None
    chk.known_keys(raw, SELECT_KEYS, "alarm_log.select")
    code = chk.need(raw, "code", "alarm_log.select", str)
    current = chk.need(raw, "current", "alarm_log.select", int)
    past = chk.need(raw, "past", "alarm_log.select", int)
    if code is None or current is None or past is None:
        return None
    entry = entries.get(code.upper())
    if entry is None or not (entry.readable and entry.writable):
        chk.bad("alarm_log.select.code", f"names no readable and writable entry: {code!r}")
        return None
    if past < 1 or not entry.min <= current <= entry.max or not entry.min <= past <= entry.max:
        chk.bad("alarm_log.select", f"current and 1..past must lie in {entry.code}'s range {entry.min}..{entry.max}")
        return None
    return RecordSelector(entry.code, current, past)
