"""Restoring a backup: plan, apply with rollback on failure, factory reset."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

from servotool.drive import Drive, NotOnDrive
from servotool.errors import DeviceError, ModbusException, ServoError, UsageError
from servotool.model.codec import format_value
from servotool.model.profile import Entry, Profile, can_save
from servotool.ops.backup import Backup, auto_backup, auto_path, load, save, take
from servotool.ops.params import read_settings, select
from servotool.words import agree, count

# Exceptions by which a drive refuses writes at an address (illegal function, illegal data address): the entry is
# reported and the restore goes on (_refused_address). Any other failure (a refused value, no answer) rolls the
# restore back.
REFUSED_ADDRESS = (1, 2)
EFFECT_ORDER = {"immediate": 0, "unknown": 1, "servo_off": 2, "power_cycle": 3}


@dataclass
class RestoreChanges:
    changes: list[tuple[Entry, int, int]]  # entry, current, target (in write order)
    skipped: list[tuple[Entry, str]]
    missing: list[Entry] = field(default_factory=list)  # in the backup, but the drive lacks them
    # Values RAM holds already but whose stored copy cannot be proven (EEPROM is not readable over Modbus): written
    # again under the EEPROM setting, as `param set --save` does
    again: list[tuple[Entry, int]] = field(default_factory=list)
    store: bool = False  # the drive's store function runs even when nothing differs (a RAM drive that has one)
    ram_only: bool = False  # --ram-only: compared with RAM, and only what differs there is written

    @property
    def empty(self) -> bool:
        """Nothing to write and nothing to store."""
        return not self.changes and not self.again and not self.store

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
    ram_only: bool = False,
) -> RestoreChanges:
    """Entries whose value (current: as read, i.e. RAM) differs, immediate ones first; axis-specific (copy: false)
    ones only when named. Where a read does not show the stored copy (eeprom.reads_are_stored), the backup's other
    values go in `again`, to be written under the EEPROM setting, or on a drive whose store function saves all
    of RAM, `store` is set; ram_only leaves both out (what EEPROM holds is then not compared)."""
    from servotool.ops.eeprom import reads_are_stored

    named = {profile.entry(c).code for c in include or []}
    if only is not None and only not in {e.group for e in profile.entries}:
        raise UsageError(f"unknown group '{only}' for profile {profile.id}")
    changes, skipped, missing = [], [], []
    same: list[tuple[Entry, int]] = []
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
        else:
            same.append((e, target))
    changes.sort(key=lambda c: EFFECT_ORDER.get(c[0].effect, 1))
    mode = profile.persistence.mode
    unproven = not ram_only and not reads_are_stored(profile)
    again = same if unproven and mode == "switchable" else []
    store = unproven and mode == "ram" and can_save(profile)
    return RestoreChanges(changes, skipped, missing, again, store, ram_only)


@dataclass
class RestoreReport:
    auto_backup: Path
    written: list[Entry]
    plan: RestoreChanges
    persisted: bool = True  # False: the drive keeps the values in RAM only (lost at power-off)
    refused: list[tuple[Entry, str]] = field(default_factory=list)  # the drive does not take writes there
    stored_again: list[Entry] = field(default_factory=list)  # plan.again, written under the EEPROM setting


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
    from servotool.ops.params import write_run, write_runs

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
    again: list[Entry] = []
    failed: tuple[str, ServoError, list[str], dict[str, str]] | None = None
    refused: list[tuple[Entry, str]] = []
    kept: dict[str, bool] = {}
    targets = {e.code: new for e, _, new in plan.changes}
    # One request per change, in the plan's order (its effects' order); the values written again for EEPROM in as
    # few requests as the drive takes (adjacent ones in one FC16 request, split when the drive refuses one).
    queue = [[(e, before.values.get(e.code, old), new)] for e, old, new in plan.changes]
    queue += write_runs(drive, [(e, raw, raw) for e, raw in sorted(plan.again, key=lambda a: a[0].address)])
    with journal.operation(drive, "restore", auto, targets):
        # A backup holds the drive's stored settings, so the restored values (and any rollback) go to EEPROM the
        # way the profile says: at once, by flipping a RAM/EEPROM switch for the batch, or by one save at the end.
        try:
            with persistence(drive, save=True) as kept:
                while queue:
                    run = queue.pop(0)
                    try:
                        write_run(drive, run)
                    except ServoError as exc:
                        if _refused_address(exc):
                            if len(run) > 1:  # which entry the drive refuses: one request each
                                queue[:0] = [[item] for item in run]
                                continue
                            refused.append((run[0][0], str(exc)))  # an exception reply: nothing was written
                            continue
                        # The failed entries too: a write that did not read back may still have changed them.
                        rolled, undo_failed = roll_back(drive, [*done, *(e for e, _, _ in run)], before.values)
                        failed = (run[0][0].code, exc, rolled, undo_failed)
                        break
                    for entry, _old, _new in run:
                        (done if entry.code in targets else again).append(entry)
                        if progress:
                            progress(entry)
        except ServoError as exc:  # the EEPROM switch could not be changed or put back
            if failed is None:
                failed = (drive.profile.persistence.switch_code or "the EEPROM switch", exc, [], {})
        if failed is not None:
            raise _account(drive, failed, [e.code for e in done], before.values, auto, kept, backup.path)
    return RestoreReport(auto, done, plan, bool(kept["persisted"]), refused, again)


def _refused_address(exc: ServoError) -> bool:
    """An exception reply by which the drive refuses writes at an address: reported, and the restore goes on."""
    return isinstance(exc, ModbusException) and exc.code in REFUSED_ADDRESS and not isinstance(exc, NotOnDrive)


def _account(
    drive: Drive,
    failed: tuple[str, ServoError, list[str], dict[str, str]],
    written: list[str],
    snapshot: dict[str, int],
    auto: Path,
    kept: dict[str, bool],
    source: Path | None,
) -> RestoreFailed:
    """The RestoreFailed for a stopped restore. The rollback read back every entry the restore touched (equal to
    the automatic backup, or written back and verified): that is the account, and only the entries it could not
    undo are read again, so a fault on one last read never hides what was rolled back."""
    code, cause, rolled, undo_failed = failed
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

    now = {c: _read_again(drive, c) for c in undo_failed}
    unknown = [c for c, raw in now.items() if raw is None]
    differ = [c for c, raw in now.items() if raw is not None and raw != snapshot[c]]
    if not unknown and not differ:
        if not written and not rolled and not undo_failed:
            state = f"nothing was changed: the drive is as the automatic backup {auto} recorded it"
            return failure(state, None, True, [])
        return failure(
            f"rolled back {len(written)} written entries; read back, the drive equals the automatic backup {auto}",
            None,
            True,
            [],
        )
    back = f"rolled back {', '.join(rolled)} (verified by read-back)" if rolled else "rolled back nothing"
    shown = ", ".join(
        f"{c} is {format_value(drive.profile.entry(c), now[c] or 0)}, was "
        f"{format_value(drive.profile.entry(c), snapshot[c])}"
        for c in differ[:6]
    )
    more = f" and {len(differ) - 6} more" if len(differ) > 6 else ""
    verb = agree(len(differ), "differs", "differ")
    if unknown:
        whys = "; ".join(f"{c}: {undo_failed[c]}" for c in unknown)
        also = f"; {count(len(differ), 'entry')} {verb} from the automatic backup {auto}: {shown}{more}"
        return failure(
            f"{wrote}; {back}; {', '.join(unknown)} could not be undone nor read back, so "
            f"{agree(len(unknown), 'its', 'their')} state is UNKNOWN ({whys}){also if differ else ''}",
            "compare",
            None,
            differ,
        )
    whys = "; ".join(f"{c} ({undo_failed[c]})" for c in differ)
    return failure(
        f"{wrote}; rollback incomplete (could not undo {whys}): {count(len(differ), 'entry')} {verb} from the "
        f"automatic backup {auto}: {shown}{more}",
        "restore",
        False,
        differ,
    )


ATTEMPTS = 3  # a flaky line drops a request now and then: an account is worth a few more tries


def _read_again(drive: Drive, code: str) -> int | None:
    """One entry as read from the drive, None when it does not answer after a few tries."""
    for _ in range(ATTEMPTS):
        try:
            return drive.read_entries([drive.profile.entry(code)])[0].raw
        except ServoError:
            continue
    return None


def roll_back(drive: Drive, touched: list[Entry], snapshot: dict[str, int]) -> tuple[list[str], dict[str, str]]:
    """Put touched entries back to the snapshot, newest first (each tried a few times); returns (the entries
    written back, each verified by read-back; code -> why for those that could not be undone). Every other
    touched entry was read back equal to the snapshot."""
    from servotool.ops.params import write_one

    rolled: list[str] = []
    undo_failed: dict[str, str] = {}
    dead = 0
    for e in reversed(touched):
        if dead >= 2:  # no answer at all, twice: every further attempt would time out too
            undo_failed[e.code] = "not tried: the drive stopped answering"
            continue
        for attempt in range(ATTEMPTS):
            try:
                now = drive.read_entries([e])[0].raw
                if now != snapshot[e.code]:
                    write_one(drive, e, snapshot[e.code], now)
                    rolled.append(e.code)
                break
            except ServoError as again:
                if attempt == ATTEMPTS - 1:
                    undo_failed[e.code] = str(again)
                    if isinstance(again, DeviceError) and not isinstance(again, ModbusException):
                        dead += 1
    return rolled, undo_failed


def restore_file(drive: Drive, path: Path, notice: Notice | None = None) -> str:
    """Plan step: restore a backup file completely (no prompts)."""
    b = load(path, drive.profile)
    current = read_settings(drive)
    rplan = restore_changes(drive.profile, b, current)
    if rplan.empty:
        return "nothing to restore: the drive already matches"
    report = restore(drive, b, rplan, notice=notice)
    left = [f"{e.code} not on this drive" for e in rplan.missing] + [
        f"{e.code} refused by the drive" for e, _ in report.refused
    ]
    again = f", {len(report.stored_again)} more written again to store them" if report.stored_again else ""
    return f"{count(len(report.written), 'entry')} restored{again} (automatic backup {report.auto_backup})" + (
        f"; left out: {', '.join(left)}" if left else ""
    )


def factory_reset(drive: Drive, notice: Notice | None = None, progress: Callable[[int], None] | None = None) -> Path:
    """Automatic backup (progress: entries read), then the profile's factory-reset function (a line in the change
    log naming the backup: the values it replaced are there)."""
    drive.profile.need_role("factory_reset", "param reset")
    check_servo_off(drive, [e for e in drive.profile.of_class("Pn") if e.effect == "servo_off"], "a factory reset")
    auto = auto_backup(drive, "before-reset", progress)
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    drive.trigger("factory_reset", "param reset")
    from servotool.ops.changelog import event

    event(drive, "factory_reset", auto_backup=str(auto))
    return auto


def not_at_default(drive: Drive, progress: Callable[[int], None] | None = None) -> list[tuple[Entry, int]]:
    """Readable parameters whose value differs from the profile's factory default (entry, raw)."""
    return [
        (r.entry, r.raw)
        for r in drive.read_entries(select(drive.profile), partial=True, progress=progress)
        if r.entry.default is not None and r.raw != r.entry.default
    ]
