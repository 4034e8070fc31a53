"""The drive's EEPROM rule: RAM/EEPROM switch, save triggers, and keeping transient writes out of EEPROM."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.profile import Entry, Profile, can_save


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
