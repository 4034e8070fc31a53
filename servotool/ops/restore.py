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
from servotool.ops.params import read_settings, select
from servotool.words import agree, count

# Exceptions by which a drive refuses writes at an address (illegal function, illegal data address): the entry is
# reported and the restore goes on. Any other failure (a refused value, no answer) rolls the restore back.
REFUSED_ADDRESS = (1, 2)
EFFECT_ORDER = {"immediate": 0, "unknown": 1, "servo_off": 2, "power_cycle": 3}


@dataclass
class RestoreChanges:
    changes: list[tuple[Entry, int, int]]  # entry, current, target (in write order)
    skipped: list[tuple[Entry, str]]
    missing: list[Entry] = field(default_factory=list)  # in the backup, but the drive lacks them

    @property
    def needs_power_cycle(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "power_cycle"]

    @property
    def needs_servo_off(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "servo_off"]


def restore_changes(
    profile: Profile,
    backup: Backup,
    current: dict[str, int],
    *,
    only: str | None = None,
    include: list[str] | None = None,
) -> RestoreChanges:
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
        if code not in current:  # the drive lacks it (read_entries(partial=True) left it out)
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
    persisted: bool = True  # False: the drive keeps the values in RAM only (lost at power-off)
    refused: list[tuple[Entry, str]] = field(default_factory=list)  # the drive does not take writes there


class RestoreFailed(ServoError):
    """A restore that stopped midway, with its account: where and why it stopped, which entries it wrote and rolled
    back, how the drive compares with the automatic backup (read from it), and the EEPROM switch.

    `equals_backup` is True/False as read back, None when the drive stopped answering. `next_step` is what to do
    with the automatic backup: "compare" (state unknown), "restore" (entries differ) or None (nothing to do).
    The exit code is the cause's: 1 when the drive or link refused, 3 when a value did not read back.
    """

    ADVICE: ClassVar[dict[str, str]] = {
        "compare": ": when it does, compare it with the automatic backup {auto} and restore that file if needed",
        "restore": "; restore the automatic backup {auto} once the cause is fixed",
    }

    def __init__(
        self,
        code: str,
        cause: ServoError,
        state: str,
        auto_backup: Path,
        next_step: str | None,
        *,
        written: list[str] | None = None,
        rolled_back: list[str] | None = None,
        equals_backup: bool | None = None,
        differ: list[str] | None = None,
        switch_note: str = "",
        source: Path | None = None,
    ) -> None:
        self.code, self.cause, self.state = code, cause, state
        self.auto_backup, self.next_step = auto_backup, next_step
        self.written, self.rolled_back = written or [], rolled_back or []
        self.equals_backup, self.differ, self.switch_note = equals_backup, differ or [], switch_note
        self.source = source  # the backup file being restored: the way to finish once the cause is fixed
        self.exit_code = cause.exit_code
        super().__init__(self.facts() + self.ADVICE.get(next_step or "", "").format(auto=auto_backup))

    def facts(self) -> str:
        """Where it stopped, why, and the drive's state after the rollback (without the advice)."""
        return f"restore stopped at {self.code}: {self.cause}; {self.state}{self.switch_note}"


Notice = Callable[[str], None]


def check_servo_off(drive: Drive, entries: list[Entry], what: str) -> None:
    """Refuse before any write when entries that may only change with the servo off meet a running servo."""
    from servotool.ops.status import servo_is_on

    if entries and servo_is_on(drive):
        codes = ", ".join(e.code for e in entries[:6]) + (" ..." if len(entries) > 6 else "")
        raise UsageError(
            f"{what} changes {codes}, which the drive accepts only with the servo off: switch the servo off first "
            "('servotool stop')"
        )


def restore(
    drive: Drive,
    backup: Backup,
    plan: RestoreChanges,
    progress: Callable[[Entry], None] | None = None,
    notice: Notice | None = None,
    backup_progress: Callable[[int], None] | None = None,
) -> RestoreReport:
    """Automatic backup first (backup_progress: entries read), then write and verify each change (progress: each
    entry written); on failure, roll back what was changed and raise RestoreFailed with the account of the drive's
    state."""
    from servotool.ops import journal
    from servotool.ops.eeprom import persistence
    from servotool.ops.params import write_one

    check_servo_off(drive, plan.needs_servo_off, "the restore")
    try:
        before = take(drive, backup_progress)
    except ServoError as exc:
        exc.args = (f"{exc}; nothing was written (the automatic backup comes first)",)
        raise
    auto = save(before, drive.profile, auto_path(drive, "before-restore"))
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    done: list[Entry] = []
    failed: tuple[str, ServoError, list[str], list[str]] | None = None
    refused: list[tuple[Entry, str]] = []
    kept: dict[str, bool] = {}
    targets = {e.code: new for e, _, new in plan.changes}
    with journal.operation(drive, "restore", auto, targets):
        # A backup holds the drive's stored settings, so the restored values (and any rollback) go to EEPROM the
        # way the profile says: at once, by flipping a RAM/EEPROM switch for the batch, or by one save at the end.
        try:
            with persistence(drive, save=True) as kept:
                for entry, old, new in plan.changes:
                    try:
                        write_one(drive, entry, new, before.values.get(entry.code, old))
                    except ServoError as exc:
                        if (
                            isinstance(exc, ModbusException)
                            and exc.code in REFUSED_ADDRESS
                            and not isinstance(exc, NotOnDrive)
                        ):
                            refused.append((entry, str(exc)))  # an exception reply: nothing was written; go on
                            continue
                        # The failed entry too: a write that did not read back may still have changed it.
                        rolled, undo_failed = _roll_back(drive, [*done, entry], before.values)
                        failed = (entry.code, exc, rolled, undo_failed)
                        break
                    done.append(entry)
                    if progress:
                        progress(entry)
        except ServoError as exc:  # the EEPROM switch could not be changed or put back
            if failed is None:
                failed = (drive.profile.persistence.switch_code or "the EEPROM switch", exc, [], [])
        if failed is not None:
            raise _account(drive, failed, [e.code for e in done], before.values, auto, kept, backup.path)
    return RestoreReport(auto, done, plan, bool(kept["persisted"]), refused)


def _account(
    drive: Drive,
    failed: tuple[str, ServoError, list[str], list[str]],
    written: list[str],
    snapshot: dict[str, int],
    auto: Path,
    kept: dict[str, bool],
    source: Path | None,
) -> RestoreFailed:
    """The RestoreFailed for a stopped restore: the drive is read to say how it compares with the backup."""
    code, cause, rolled, undo_failed = failed
    after = _read_all(drive)
    switch_note = ""
    if kept.get("switch_back") is False:
        p = drive.profile.persistence
        switch_note = (
            f"; {p.switch_code} (the EEPROM switch) could not be put back: the next servotool command "
            f"on this drive puts it back, from the host's journal"
        )
    listed = ", ".join(written[:6]) + (" ..." if len(written) > 6 else "")
    wrote = f"wrote {len(written)} of the planned entries" + (f" ({listed})" if written else "")

    def failure(state: str, next_step: str | None, equal: bool | None, differ: list[str]) -> RestoreFailed:
        return RestoreFailed(
            code,
            cause,
            state,
            auto,
            next_step,
            written=written,
            rolled_back=rolled,
            equals_backup=equal,
            differ=differ,
            switch_note=switch_note,
            source=source,
        )

    if after is None:
        return failure(f"{wrote}; the drive no longer answers, so its state is unknown", "compare", None, [])
    # The EEPROM switch is flipped for the batch on purpose (and put back when it ends): not a difference.
    differ = [c for c, raw in snapshot.items() if after.get(c) != raw and not drive.profile.persistence.is_switch(c)]
    if not differ:
        return failure(
            f"rolled back {len(written)} written entries; read back, the drive equals the automatic backup {auto}",
            None,
            True,
            [],
        )
    shown = ", ".join(
        f"{c} is {format_value(drive.profile.entry(c), after[c])}, was "
        f"{format_value(drive.profile.entry(c), snapshot[c])}"
        for c in differ[:6]
    )
    more = f" and {len(differ) - 6} more" if len(differ) > 6 else ""
    why = f" (could not undo {'; '.join(undo_failed)})" if undo_failed else ""
    verb = agree(len(differ), "differs", "differ")
    return failure(
        f"{wrote}; rollback incomplete{why}: {count(len(differ), 'entry')} {verb} from the automatic "
        f"backup {auto}: {shown}{more}",
        "restore",
        False,
        differ,
    )


ATTEMPTS = 3  # a flaky line drops a request now and then: an account is worth a few more tries


def _read_all(drive: Drive) -> dict[str, int] | None:
    """Every parameter as read from the drive, None when it does not answer after a few tries."""
    for _ in range(ATTEMPTS):
        try:
            return read_settings(drive)
        except ServoError:
            continue
    return None


def _roll_back(drive: Drive, touched: list[Entry], snapshot: dict[str, int]) -> tuple[list[str], list[str]]:
    """Put touched entries back to the snapshot, newest first (each tried a few times); returns (the entries
    written back, those that could not be undone with why)."""
    from servotool.ops.params import write_one

    rolled: list[str] = []
    undo_failed: list[str] = []
    dead = 0
    for e in reversed(touched):
        for attempt in range(ATTEMPTS):
            try:
                now = drive.read_entries([e])[0].raw
                if now != snapshot[e.code]:
                    write_one(drive, e, snapshot[e.code], now)
                    rolled.append(e.code)
                break
            except ServoError as again:
                if attempt == ATTEMPTS - 1:
                    undo_failed.append(f"{e.code} ({again})")
                    if isinstance(again, DeviceError) and not isinstance(again, ModbusException):
                        dead += 1
        if dead >= 2:
            break  # no answer at all, twice: every further attempt would time out too
    return rolled, undo_failed


def restore_file(drive: Drive, path: Path, notice: Notice | None = None) -> str:
    """Plan step: restore a backup file completely (no prompts)."""
    b = load(path, drive.profile)
    current = read_settings(drive)
    rplan = restore_changes(drive.profile, b, current)
    if not rplan.changes:
        return "nothing to restore: the drive already matches"
    report = restore(drive, b, rplan, notice=notice)
    left = [f"{e.code} not on this drive" for e in rplan.missing] + [
        f"{e.code} refused by the drive" for e, _ in report.refused
    ]
    return f"{count(len(report.written), 'entry')} restored (automatic backup {report.auto_backup})" + (
        f"; left out: {', '.join(left)}" if left else ""
    )


def factory_reset(drive: Drive, notice: Notice | None = None, progress: Callable[[int], None] | None = None) -> Path:
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
    return [
        (r.entry, r.raw)
        for r in drive.read_entries(select(drive.profile), partial=True, progress=progress)
        if r.entry.default is not None and r.raw != r.entry.default
    ]
