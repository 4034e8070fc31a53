"""The drive's EEPROM rule: RAM/EEPROM switch, save triggers, and keeping transient writes out of EEPROM."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from servotool.drive import Drive
from servotool.errors import ServoError, UsageError, VerifyError
from servotool.model.codec import format_value
from servotool.model.profile import Entry, Profile, can_save
from servotool.words import agree


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
def _switched(
    drive: Drive, entry: Entry, current: int, wanted: int, state: dict[str, bool] | None = None, purpose: str = ""
) -> Iterator[None]:
    """Run the block with the switch at `wanted`, journaled on the host, and put it back (verified) on every exit
    path; the journal record goes only once the switch is confirmed back, else the next command finishes it.
    The switch is read back once written, before the block runs, and again when the block ends, before it is put
    back: a drive that acknowledges the switch but ignores it (or drops it midway) ends the batch with
    SwitchNotTaken, so no write is ever reported as stored (or kept out of EEPROM) on the switch's word alone.
    state['switch_back'] says whether it was put back; `purpose` words what the switch was set for."""
    from servotool.ops import journal

    if wanted == current:
        yield
        return
    failing = True
    try:
        # Inside the try: a Ctrl-C that lands while the switch is being written still puts it back.
        journal.note_switch(drive, entry.code, current)
        drive.write_raw(entry, wanted)
        _confirm_switch(drive, entry, wanted, purpose, "before any value was written: nothing was written")
        yield
        _confirm_switch(
            drive,
            entry,
            wanted,
            purpose,
            "when the writes ended: the values written may NOT be where the command meant them to go",
        )
        failing = False
    finally:
        _put_back(drive, entry, current, failing, state)


class SwitchNotTaken(VerifyError):
    """The drive acknowledged the EEPROM switch but does not hold it: where the writes go is not what was asked."""


def _confirm_switch(drive: Drive, entry: Entry, wanted: int, purpose: str, when: str) -> None:
    """Read the switch back; SwitchNotTaken naming the drive's value and what that leaves when it is not `wanted`."""
    now = drive.read_entries([entry])[0].raw
    if now != wanted:
        raise SwitchNotTaken(
            f"{entry.code} (the EEPROM switch) was set to {format_value(entry, wanted)}"
            f"{f' to {purpose}' if purpose else ''} and the drive acknowledged it, but it reads back "
            f"{format_value(entry, now)} {when}"
        )


def _put_back(drive: Drive, entry: Entry, raw: int, failing: bool, state: dict[str, bool] | None) -> None:
    """The switch back, verified, tried a few times (an interrupted request may leave the line out of step);
    the journal record goes once it is confirmed. A Ctrl-C during the put-back does not stop it while the drive
    answers: it is raised once the switch is back."""
    from servotool.ops import journal

    interrupt: KeyboardInterrupt | None = None
    for attempt in range(3):
        try:
            drive.write_verified(entry, raw)
            journal.clear_switch(drive)
        except (ServoError, KeyboardInterrupt) as exc:
            if isinstance(exc, KeyboardInterrupt):
                interrupt = exc
            if attempt < 2:
                continue
            if state is not None:
                state["switch_back"] = False
            if interrupt is not None:
                raise interrupt from None
            if not failing:
                raise  # otherwise the first error is the one to report
            return
        if state is not None:
            state["switch_back"] = True
        if interrupt is not None:
            raise interrupt
        return


@contextmanager
def ram_writes(drive: Drive) -> Iterator[None]:
    """Keep transient writes (a motion's speed, ramp, servo-on) out of EEPROM where the drive has a switch
    (IS620P's factory H0C-13 = 1 stores every write); the switch is put back afterwards. The port's lock is held
    on every drive: the motion's settings are journaled (ops.journal.note_settings) for the next command to put
    back if this process dies, and only a dead holder's record may be recovered."""
    from servotool.ops.changelog import temporary
    from servotool.ops.journal import port_lock

    with port_lock(drive), temporary(drive):
        if drive.profile.persistence.mode != "switchable":
            yield
            return
        entry, current, _eeprom, ram = switch_state(drive)
        with _switched(drive, entry, current, ram, purpose="keep the motion's settings out of EEPROM"):
            yield


def reads_are_stored(profile: Profile) -> bool:
    """Whether a value read from the drive is also the one it stores: only on a drive that stores every write.
    Elsewhere a read shows RAM, which a RAM-only write (or one stored and then changed in RAM) sets apart from
    EEPROM, and EEPROM cannot be read over Modbus."""
    return profile.persistence.mode == "immediate"


def compared_memory(profile: Profile) -> str:
    """What a comparison with the drive's values compares, for the user: 'RAM' or 'RAM (= EEPROM ...)'."""
    return "RAM (= EEPROM: the drive stores every write)" if reads_are_stored(profile) else "RAM"


def ram_only_warning(profile: Profile) -> str:
    """What to tell the user when written values are in RAM only, and how to make them survive a power cycle."""
    hint = "use --save" if can_save(profile) else profile.persistence.note
    return f"not saved to EEPROM: the drive keeps these values only until power-off ({hint})"


def check_save_request(profile: Profile, save: bool | None) -> None:
    """Refuse an explicit --save, before any write, on a drive that cannot store over Modbus."""
    if save and not can_save(profile):
        raise UsageError(f"{profile.model} cannot store parameters over Modbus: {profile.persistence.note}")


def will_persist(drive: Drive, save: bool | None) -> bool:
    """Whether writes made now with this --save choice survive a power cycle (reads the switch)."""
    p = drive.profile.persistence
    if p.mode == "immediate":
        return True
    if p.mode == "ram":
        return bool(save) and can_save(drive.profile)
    if save is not None:
        return save
    _entry, current, eeprom, _ram = switch_state(drive)
    return current == eeprom


def check_power_cycle(drive: Drive, entries: list[Entry], save: bool | None) -> None:
    """Refuse, before any write, a parameter that takes effect only after a power cycle when the write would be
    in RAM only: the power cycle that would apply it discards it."""
    later = [e.code for e in entries if e.effect == "power_cycle"]
    if not later or will_persist(drive, save):
        return
    codes = ", ".join(later)
    how = (
        "store it with --save"
        if can_save(drive.profile) and save is not False
        else "drop --no-save"
        if can_save(drive.profile)
        else drive.profile.persistence.note
    )
    raise UsageError(
        f"{codes} {agree(len(later), 'takes', 'take')} effect only after a power cycle, and "
        f"written in RAM only {agree(len(later), 'it', 'they')} would be lost by that power cycle: {how}"
    )


@contextmanager
def persistence(drive: Drive, save: bool | None) -> Iterator[dict[str, bool]]:
    """Apply the drive's EEPROM rule around a batch of writes; yields {'persisted': bool} once the batch is done.

    save=None leaves the drive as it is (a RAM-only drive stays RAM-only); save=True makes the writes permanent
    with as few EEPROM writes as the drive allows; save=False keeps them out of EEPROM where the drive lets us.
    The batch holds the port's lock, so no other servotool process writes while the switch is changed. Its
    changes are history: each goes into the drive's change log with the memory it went to (ops.changelog).
    """
    from servotool.ops import changelog
    from servotool.ops.journal import port_lock

    p = drive.profile.persistence
    state = {"persisted": p.mode == "immediate"}
    with port_lock(drive):
        if p.mode == "switchable":
            entry, current, eeprom, ram = switch_state(drive)
            wanted = current if save is None else (eeprom if save else ram)
            state["persisted"] = wanted == eeprom
            purpose = "store the writes in EEPROM" if wanted == eeprom else "keep the writes out of EEPROM"
            memory = changelog.EEPROM if wanted == eeprom else changelog.RAM
            with _switched(drive, entry, current, wanted, state, purpose), changelog.lasting(drive, memory):
                yield state
            return
        with changelog.lasting(drive, changelog.EEPROM if p.mode == "immediate" else changelog.RAM):
            yield state
        if p.mode == "ram" and save and can_save(drive.profile):
            drive.trigger("eeprom_save", "--save")
            state["persisted"] = True
            changelog.event(drive, "store", memory=changelog.EEPROM, note="the drive's store function: RAM to EEPROM")
