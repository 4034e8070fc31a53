"""Restoring a backup: plan, apply with rollback on failure, factory reset."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from servotool.drive import Drive, NotOnDrive
from servotool.errors import DeviceError, ModbusException, ServoError, UsageError
from servotool.model.codec import format_value
from servotool.model.profile import Entry, Profile
from servotool.ops.backup import Backup, auto_backup, auto_path, load, save, take
from servotool.ops.params import select

# Exceptions by which a drive refuses writes at an address (illegal function, illegal data address): the entry is
# reported and the restore goes on. Any other failure (a refused value, no answer) rolls the restore back.
REFUSED_ADDRESS = (1, 2)
EFFECT_ORDER = {"immediate": 0, "unknown": 1, "servo_off": 2, "power_cycle": 3}


@dataclass
class RestoreChanges:
    changes: list[tuple[Entry, int, int]]       # entry, current, target (in write order)
    skipped: list[tuple[Entry, str]]
    missing: list[Entry] = field(default_factory=list)   # in the backup, but the drive lacks them

    @property
    def needs_power_cycle(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "power_cycle"]

    @property
    def needs_servo_off(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "servo_off"]


def restore_changes(profile: Profile, backup: Backup, current: dict[str, int], *, only: str | None = None,
                 include: list[str] | None = None) -> RestoreChanges:
    """Only entries that differ; axis-specific (copy: false) ones only when named; immediate ones first."""
    named = {profile.entry(c).code for c in include or []}
    if only is not None and only not in {e.group for e in profile.entries}:
        raise UsageError(f"unknown group '{only}' for profile {profile.id}")
    changes, skipped, missing = [], [], []
    for code, target in backup.values.items():
        e = profile.entry(code)
        if only is not None and e.group != only and e.code not in named:
            continue
        if not e.writable:
            continue
        if code not in current:          # the drive lacks it (read_entries(partial=True) left it out)
            missing.append(e)
            continue
        if profile.persistence.is_switch(e.code):
            # Writing it would change where every later value goes; the restore sets it for its own writes.
            if current.get(code) != target:
                skipped.append((e, "EEPROM write switch: the restore sets it for its writes and leaves it as it was"))
            continue
        if not e.copy and e.code not in named:
            if current.get(code) != target:
                skipped.append((e, "axis-specific (name it with --include to restore)"))
            continue
        if current.get(code) != target:
            changes.append((e, current[code], target))
    changes.sort(key=lambda c: EFFECT_ORDER.get(c[0].effect, 1))
    return RestoreChanges(changes, skipped, missing)


@dataclass
class RestoreReport:
    auto_backup: Path
    written: list[Entry]
    plan: RestoreChanges
    persisted: bool = True      # False: the drive keeps the values in RAM only (lost at power-off)
    refused: list[tuple[Entry, str]] = field(default_factory=list)   # the drive does not take writes there


class RestoreFailed(ServoError):
    """A write failed midway; the message says exactly what state the drive is in.

    `next_step` is what the user should do with the automatic backup: "compare" (the drive stopped answering,
    so its state is unknown), "restore" (the rollback left entries different) or None (rolled back fully).
    The exit code is the cause's: 1 when the drive or link refused, 3 when a value did not read back.
    """

    ADVICE: ClassVar[dict[str, str]] = {
        "compare": ": when it does, compare it with the automatic backup {auto} and restore that file if needed",
        "restore": "; restore the automatic backup {auto} once the cause is fixed",
    }

    def __init__(self, code: str, cause: ServoError, state: str, auto_backup: Path, next_step: str | None) -> None:
        self.code, self.cause, self.state = code, cause, state
        self.auto_backup, self.next_step = auto_backup, next_step
        self.exit_code = cause.exit_code
        super().__init__(self.facts() + self.ADVICE.get(next_step or "", "").format(auto=auto_backup))

    def facts(self) -> str:
        """Where it stopped, why, and the drive's state after the rollback (without the advice)."""
        return f"restore stopped at {self.code}: {self.cause}; {self.state}"


Notice = Callable[[str], None]


def check_servo_off(drive: Drive, entries: list[Entry], what: str) -> None:
    """Refuse before any write when entries that may only change with the servo off meet a running servo."""
    from servotool.ops.status import servo_is_on

    if entries and servo_is_on(drive):
        codes = ", ".join(e.code for e in entries[:6]) + (" ..." if len(entries) > 6 else "")
        raise UsageError(f"{what} changes {codes}, which the drive accepts only with the servo off: "
                         f"switch the servo off first")


def restore(drive: Drive, backup: Backup, plan: RestoreChanges,
            progress: Callable[[Entry], None] | None = None, notice: Notice | None = None) -> RestoreReport:
    """Automatic backup first, then write and verify each change; on failure, roll back what was changed."""
    from servotool.ops.eeprom import persistence
    from servotool.ops.params import write_one

    check_servo_off(drive, plan.needs_servo_off, "the restore")
    before = take(drive)
    auto = save(before, drive.profile, auto_path(drive, "before-restore"))
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    done: list[Entry] = []
    refused: list[tuple[Entry, str]] = []
    # A backup holds the drive's stored settings, so the restored values (and any rollback) go to EEPROM the
    # way the profile says: at once, by flipping a RAM/EEPROM switch for the batch, or by one save at the end.
    with persistence(drive, save=True) as kept:
        for entry, old, new in plan.changes:
            try:
                write_one(drive, entry, new, before.values.get(entry.code, old))
            except ServoError as exc:
                if isinstance(exc, ModbusException) and exc.code in REFUSED_ADDRESS and not isinstance(exc, NotOnDrive):
                    refused.append((entry, str(exc)))     # an exception reply: nothing was written; go on
                    continue
                # The failed entry too: a write that did not read back may still have changed it.
                state, next_step = _roll_back(drive, [*done, entry], before.values, auto)
                raise RestoreFailed(entry.code, exc, state, auto, next_step) from None
            done.append(entry)
            if progress:
                progress(entry)
    return RestoreReport(auto, done, plan, kept["persisted"], refused)


def _roll_back(drive: Drive, touched: list[Entry], snapshot: dict[str, int], auto: Path) -> tuple[str, str | None]:
    """Put touched entries back to the snapshot, newest first, then say how the whole drive compares to it
    (and the RestoreFailed.next_step that follows)."""
    from servotool.ops.params import write_one

    undo_failed: list[str] = []
    for e in reversed(touched):
        try:
            now = drive.read_entries([e])[0].raw
            if now != snapshot[e.code]:
                write_one(drive, e, snapshot[e.code], now)
        except ServoError as again:
            undo_failed.append(f"{e.code} ({again})")
            if isinstance(again, DeviceError) and not isinstance(again, ModbusException):
                break                        # no answer at all: every further attempt would time out too
    try:
        after = {r.entry.code: r.raw for r in drive.read_entries(select(drive.profile), partial=True)}
    except ServoError as exc:
        return f"the drive no longer answers ({exc}), so its state is unknown", "compare"
    # The EEPROM switch is flipped for the batch on purpose (and put back when it ends): not a difference.
    differ = [code for code, raw in snapshot.items()
              if after.get(code) != raw and not drive.profile.persistence.is_switch(code)]
    if not differ:
        return (f"rolled back {len(touched) - 1} written entries; read back, the drive equals the automatic "
                f"backup {auto}"), None
    shown = ", ".join(f"{c} is {format_value(drive.profile.entry(c), after[c])}, was "
                      f"{format_value(drive.profile.entry(c), snapshot[c])}" for c in differ[:6])
    more = f" and {len(differ) - 6} more" if len(differ) > 6 else ""
    why = f" (could not undo {'; '.join(undo_failed)})" if undo_failed else ""
    return f"rollback incomplete{why}: {len(differ)} entries differ from the automatic backup {auto}: {shown}{more}", \
        "restore"


def restore_file(drive: Drive, path: Path, notice: Notice | None = None) -> str:
    """Plan step: restore a backup file completely (no prompts)."""
    b = load(path, drive.profile)
    current = {r.entry.code: r.raw for r in drive.read_entries(select(drive.profile), partial=True)}
    rplan = restore_changes(drive.profile, b, current)
    if not rplan.changes:
        return "nothing to restore: the drive already matches"
    report = restore(drive, b, rplan, notice=notice)
    left = [f"{e.code} not on this drive" for e in rplan.missing] + \
        [f"{e.code} refused by the drive" for e, _ in report.refused]
    return (f"{len(report.written)} entries restored (automatic backup {report.auto_backup})"
            + (f"; left out: {', '.join(left)}" if left else ""))


def factory_reset(drive: Drive, notice: Notice | None = None,
                  progress: Callable[[int], None] | None = None) -> Path:
    """Automatic backup (progress: entries read), then the profile's factory-reset function."""
    drive.profile.need_role("factory_reset", "param reset")
    check_servo_off(drive, [e for e in drive.profile.of_class("Pn") if e.effect == "servo_off"], "a factory reset")
    auto = auto_backup(drive, "before-reset", progress)
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    drive.trigger("factory_reset", "param reset")
    return auto


def not_at_default(drive: Drive, progress: Callable[[int], None] | None = None) -> list[tuple[Entry, int]]:
    """Readable parameters whose value differs from the profile's factory default (entry, raw)."""
    return [(r.entry, r.raw) for r in drive.read_entries(select(drive.profile), partial=True, progress=progress)
            if r.entry.default is not None and r.raw != r.entry.default]
