"""Parameter operations built on Drive: select, read, validate-then-write many entries."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from servotool.codec import split_field
from servotool.drive import Drive, Reading, WriteResult
from servotool.errors import ServoError, UsageError
from servotool.profile import Entry, Profile


def select(profile: Profile, *, group: str | None = None, classes: tuple[str, ...] = ("Pn",)) -> list[Entry]:
    """Readable entries of the given classes (and group), in profile order."""
    if group is not None and group not in {e.group for e in profile.entries}:
        known = ", ".join(sorted({e.group for e in profile.entries if e.group}))
        raise UsageError(f"unknown group '{group}' for profile {profile.id} (groups: {known})")
    return [e for e in profile.entries
            if e.cls in classes and e.readable and (group is None or e.group == group)]


@dataclass(frozen=True)
class SetPlan:
    """Validated assignments with the drive's current values."""

    changes: list[tuple[Entry, int, int]]  # entry, old raw, new raw
    unchanged: list[tuple[Entry, int]]


def plan_set(drive: Drive, assignments: list[str], *, raw: bool = False) -> SetPlan:
    """Parse and range-check every CODE=VALUE, then read current values; nothing is written."""
    if not assignments:
        raise UsageError("nothing to set: give CODE=VALUE ...")
    parsed: dict[str, tuple[Entry, list[str]]] = {}
    fields_given: dict[str, set[str]] = {}
    for text in assignments:
        entry, _ = drive.parse_assignment(text, raw=raw)  # validates code/access/type/range before any I/O
        field = split_field(drive.profile, text.partition("=")[0])[1]
        if entry.code in parsed:
            # Several fields of one entry (Po175.C=2 Po175.D=3) make one write; anything else twice is a mistake.
            done = fields_given.get(entry.code)
            if field is None or done is None:
                raise UsageError(f"{entry.code} is given twice")
            if field in done:
                raise UsageError(f"{entry.code}.{field} is given twice")
            done.add(field)
        else:
            parsed[entry.code] = (entry, [])
            if field is not None:
                fields_given[entry.code] = {field}
        parsed[entry.code][1].append(text)
    current = {r.entry.code: r.raw
               for r in drive.read_entries([e for e, _ in parsed.values() if e.readable])}
    changes: list[tuple[Entry, int, int]] = []
    unchanged: list[tuple[Entry, int]] = []
    for entry, texts in parsed.values():
        old = current.get(entry.code)
        # Field input (Po001.Y=1, X=0) is relative to the drive's current value, so parse again with it.
        new = drive.parse_assignment(texts[0], raw=raw, current=old)[1]
        for text in texts[1:]:
            new = drive.parse_assignment(text, raw=raw, current=new)[1]
        if old == new:
            unchanged.append((entry, new))
        else:
            changes.append((entry, old if old is not None else new, new))
    return SetPlan(changes, unchanged)


def write_one(drive: Drive, entry: Entry, raw: int, old: int | None = None) -> WriteResult:
    """The one path every parameter write takes (set, restore, plans): write, then verify by read-back."""
    return drive.write_verified(entry, raw, old)


def write_runs(drive: Drive, changes: list[tuple[Entry, int, int]]) -> list[list[tuple[Entry, int, int]]]:
    """Split changes (in the order given) into runs one request can carry: consecutive entries at adjacent
    addresses, when the drive takes FC16, up to its max_write registers. A single entry is a run of one."""
    limits = drive.profile.limits
    runs: list[list[tuple[Entry, int, int]]] = []
    for change in changes:
        entry = change[0]
        if runs and limits.write_multiple:
            run = runs[-1]
            last = run[-1][0]
            if entry.address == last.address + last.words and \
                    sum(e.words for e, _, _ in run) + entry.words <= limits.max_write:
                run.append(change)
                continue
        runs.append([change])
    return runs


def apply_set(drive: Drive, plan: SetPlan) -> list[WriteResult]:
    """Write the planned changes in order, adjacent ones in one FC16 request (as the manuals' multi-register
    examples do), each verified by read-back."""
    results: list[WriteResult] = []
    for run in write_runs(drive, plan.changes):
        if len(run) == 1:
            entry, old, new = run[0]
            results.append(write_one(drive, entry, new, old))
        else:
            results.extend(drive.write_block_verified([(e, new, old) for e, old, new in run]))
    return results


def read_all(drive: Drive, entries: list[Entry]) -> list[Reading]:
    return drive.read_entries(entries)


def switch_state(drive: Drive) -> tuple[Entry, int, int, int]:
    """(switch entry, its raw value, raw value meaning EEPROM, raw value meaning RAM) for switchable drives."""
    p = drive.profile.persistence
    entry = drive.profile.entry(p.switch_code)
    raw = drive.read_entries([entry])[0].raw
    if p.switch_digit and entry.format == "digits":
        idx = [f.upper() for f in entry.fields].index(p.switch_digit.upper())
        shift, mask = entry.field_width * idx, (1 << entry.field_width) - 1
        base = raw & ~(mask << shift)
        return entry, raw, base | (p.switch_eeprom << shift), base | (p.switch_ram << shift)
    return entry, raw, p.switch_eeprom, p.switch_ram


@contextmanager
def ram_writes(drive: Drive) -> Iterator[None]:
    """Keep transient writes (a motion's speed, ramp, servo-on) out of EEPROM where the drive has a switch
    (IS620P's factory H0C-13 = 1 stores every write); the switch is put back afterwards."""
    if drive.profile.persistence.mode != "switchable":
        yield
        return
    entry, current, _eeprom, ram = switch_state(drive)
    if current != ram:
        drive.write_raw(entry, ram)
    failing = True
    try:
        yield
        failing = False
    finally:
        if current != ram:
            try:
                drive.write_raw(entry, current)
            except ServoError:
                if not failing:
                    raise      # otherwise the first error is the one to report


def can_save(profile: Profile) -> bool:
    """Whether values written over Modbus can be made permanent over Modbus."""
    p = profile.persistence
    return p.mode != "ram" or profile.role("eeprom_save") is not None


def ram_only_warning(profile: Profile) -> str:
    """What to tell the user when written values are in RAM only, and how to make them survive a power cycle."""
    hint = "use --save" if can_save(profile) else profile.persistence.note
    return f"not saved to EEPROM: the drive keeps these values only until power-off ({hint})"


def check_save_request(profile: Profile, save: bool | None) -> None:
    """Refuse an explicit --save, before any write, on a drive that cannot store over Modbus."""
    if save and not can_save(profile):
        raise UsageError(f"{profile.model} cannot store parameters over Modbus: {profile.persistence.note}")


@contextmanager
def persistence(drive: Drive, save: bool | None) -> Iterator[dict[str, bool]]:
    """Apply the drive's EEPROM rule around a batch of writes; yields {'persisted': bool} once the batch is done.

    save=None leaves the drive as it is (a RAM-only drive stays RAM-only); save=True makes the writes permanent
    with as few EEPROM writes as the drive allows; save=False keeps them out of EEPROM where the drive lets us.
    """
    p = drive.profile.persistence
    state = {"persisted": p.mode == "immediate"}
    if p.mode == "switchable":
        entry, current, eeprom, ram = switch_state(drive)
        wanted = current if save is None else (eeprom if save else ram)
        if wanted != current:
            drive.write_raw(entry, wanted)
        try:
            yield state
        finally:
            state["persisted"] = wanted == eeprom
            if wanted != current:
                drive.write_raw(entry, current)   # leave the switch as the user had it
        return
    yield state
    if p.mode == "ram" and save and can_save(drive.profile):
        drive.trigger("eeprom_save", "--save")
        state["persisted"] = True
