"""Declarative drive settings: the one function that brings a drive to a desired set (ops.desired) and says
whether it changed anything (`param apply`, `fleet apply`, `fleet drift`, the Ansible modules).

It reads what differs, writes only that through the one write path under the drive's EEPROM rule, reads every
desired value back, and returns the facts: each parameter before and after, "changed" or "unchanged". In check
mode it writes nothing and says what it would change. A write that fails midway rolls back what it wrote, so a
drive is left either as desired or as it was.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from servotool.drive import Drive
from servotool.errors import ServoError, VerifyError
from servotool.model.codec import format_value, json_text, json_value
from servotool.model.profile import Entry
from servotool.model.quantity import quantity
from servotool.ops.desired import DesiredSet

CHANGED, UNCHANGED, WOULD_CHANGE = "changed", "unchanged", "would change"


@dataclass(frozen=True)
class Setting:
    """One desired parameter: as the drive held it before, the value wanted, and as read back after (None in check
    mode, or when nothing was written and nothing needed to be)."""

    entry: Entry
    before: int
    desired: int
    after: int | None = None

    @property
    def differs(self) -> bool:
        return self.before != self.desired

    def as_json(self) -> dict[str, Any]:
        e = self.entry
        out: dict[str, Any] = {"code": e.code, "name": e.name, "changed": self.differs}
        for key, raw in (("before", self.before), ("desired", self.desired), ("after", self.after)):
            out[key] = None if raw is None else quantity(json_value(e, raw), e.unit)
            if raw is not None and (text := json_text(e, raw)) is not None:
                out[key]["text"] = text
        out["effect"] = e.effect
        return out


@dataclass
class ApplyResult:
    """What apply found and did: `status` is changed, unchanged or (check mode) would change."""

    status: str
    settings: list[Setting]
    check: bool
    save: bool | None
    compared: str  # the memory the comparison read: 'RAM' or 'RAM (= EEPROM ...)' (ops.eeprom.compared_memory)
    persisted: bool | None = None  # the changes survive a power cycle; None when nothing was written
    verified: bool = False  # every desired value read back equal after the writes (or found so)
    missing: list[str] = field(default_factory=list)  # desired entries the drive lacks (a backup's), left out
    skipped: list[tuple[str, str]] = field(default_factory=list)  # (code, why) a backup's entries left out

    @property
    def changes(self) -> list[Setting]:
        return [s for s in self.settings if s.differs]

    @property
    def needs_power_cycle(self) -> list[str]:
        return [s.entry.code for s in self.changes if s.entry.effect == "power_cycle"]

    def as_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "changed": self.status == CHANGED,
            "check": self.check,
            "save": self.save,
            "compared": self.compared,
            "persisted": self.persisted,
            "verified": self.verified,
            "settings": [s.as_json() for s in self.settings],
            "needs_power_cycle": self.needs_power_cycle,
            "missing": self.missing,
            "skipped": [{"code": c, "why": why} for c, why in self.skipped],
        }

    def diff_text(self) -> tuple[str, str]:
        """(before, after) as text, one 'CODE: value unit' line per changing parameter: for a diff view."""

        def line(s: Setting, raw: int) -> str:
            unit = f" {s.entry.unit}" if s.entry.unit else ""
            return f"{s.entry.code}: {format_value(s.entry, raw)}{unit}\n"

        return "".join(line(s, s.before) for s in self.changes), "".join(line(s, s.desired) for s in self.changes)


class ApplyFailed(ServoError):
    """An apply that stopped midway, with its account: where and why, what it had written, what it rolled back, and
    whether the drive is as it was. The exit code is the cause's (1 the drive or link refused, 3 a value did not
    read back)."""

    def __init__(
        self, code: str, cause: ServoError, written: list[str], rolled_back: list[str], unknown: dict[str, str]
    ) -> None:
        self.code, self.cause, self.written, self.rolled_back, self.unknown = code, cause, written, rolled_back, unknown
        self.exit_code = cause.exit_code
        if unknown:
            state = (
                f"could not undo {', '.join(f'{c} ({why})' for c, why in unknown.items())}: "
                "its state is UNKNOWN, compare with 'param get'"
            )
        elif rolled_back:
            state = f"rolled back {', '.join(rolled_back)} (verified by read-back): the drive is as it was"
        else:
            state = "nothing was changed: the drive is as it was"
        super().__init__(f"apply stopped at {code}: {cause}; {state}")

    @property
    def as_before(self) -> bool:
        return not self.unknown


def apply(drive: Drive, desired: DesiredSet, *, check: bool = False) -> ApplyResult:
    """Bring the drive to the desired set, or with check=True only say what would change (nothing is written).

    Every value is parsed and range-checked before any I/O; the current values are read, and only those that
    differ are written (adjacent ones in one request), verified by read-back, under the drive's EEPROM rule
    (desired.save) and the bus's lock, journaled so that a kill midway is accounted for by the next command. At
    the end every desired value is read again: the result is 'verified' only when all of them read as desired. A
    failure midway rolls back what was written (ApplyFailed says what the drive holds). Comparison is with what a
    read shows: RAM, which on a drive that cannot read EEPROM (ops.eeprom.reads_are_stored) may hold other values
    than EEPROM; a value RAM holds already is left as it is."""
    from servotool.ops import journal
    from servotool.ops.desired import check as check_desired
    from servotool.ops.eeprom import check_power_cycle, check_save_request, compared_memory, persistence
    from servotool.ops.params import prepare_set

    profile = drive.profile
    check_desired(desired, profile)
    check_save_request(profile, desired.save)
    compared = compared_memory(profile)
    with journal.port_lock(drive):
        plan = prepare_set(drive, list(desired.assignments), raw=desired.raw, partial=desired.from_backup)
        settings = [Setting(e, old, new) for e, old, new in plan.changes] + [
            Setting(e, raw, raw) for e, raw in plan.unchanged
        ]
        settings.sort(key=lambda s: (s.entry.address, s.entry.code))
        result = ApplyResult(
            UNCHANGED,
            settings,
            check,
            desired.save,
            compared,
            missing=[e.code for e in plan.missing],
            skipped=list(desired.skipped),
        )
        if not plan.changes:
            result.verified = True  # read just now, each as desired
            return result
        if check:
            result.status = WOULD_CHANGE
            return result
        check_power_cycle(drive, [e for e, _, _ in plan.changes], desired.save)
        targets = {e.code: new for e, _old, new in plan.changes}
        before = {e.code: old for e, old, _new in plan.changes}
        with journal.operation(drive, "param apply", None, targets, before), persistence(drive, desired.save) as kept:
            _write(drive, plan.changes, before)
        result.status, result.persisted = CHANGED, kept["persisted"]
        result.settings = _read_back(drive, settings)
        result.verified = True
    return result


def _write(drive: Drive, changes: list[tuple[Entry, int, int]], before: dict[str, int]) -> None:
    """The changes in the fewest verified requests; on a failure, what was written goes back (ApplyFailed)."""
    from servotool.ops.params import write_run, write_runs
    from servotool.ops.restore import roll_back

    done: list[Entry] = []
    for run in write_runs(drive, sorted(changes, key=lambda c: c[0].address)):
        try:
            write_run(drive, run)
        except ServoError as exc:
            # The failed run too: a write that did not read back may still have changed it.
            touched = [*done, *(e for e, _, _ in run)]
            rolled, unknown = roll_back(drive, touched, before)
            raise ApplyFailed(run[0][0].code, exc, [e.code for e in done], rolled, unknown) from None
        done += [e for e, _, _ in run]


def _read_back(drive: Drive, settings: list[Setting]) -> list[Setting]:
    """Every desired value read again, after the batch and the EEPROM switch put back: the last claim proven.
    VerifyError naming each one the drive holds otherwise."""
    readable = [s.entry for s in settings if s.entry.readable]
    now = {r.entry.code: r.raw for r in drive.read_entries(readable)}
    wrong = [s for s in settings if s.entry.code in now and now[s.entry.code] != s.desired]
    if wrong:
        told = [
            f"{s.entry.code} = {format_value(s.entry, now[s.entry.code])} (wanted {format_value(s.entry, s.desired)})"
            for s in wrong
        ]
        raise VerifyError(f"after the writes the drive reads {', '.join(told)}")
    return [Setting(s.entry, s.before, s.desired, now.get(s.entry.code)) for s in settings]
