"""A simulated drive seen from outside a Modbus session: what the CLI may learn of it and do to it.

The drive's state file is the simulator's business; callers use these functions instead of opening it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from servotool.model.profile import Entry, Profile
from servotool.sim.device import SimulatedDrive
from servotool.sim.handover import RunningSummary, running_summary
from servotool.sim.registers import RegisterBank, state_path


@dataclass(frozen=True)
class SimStatus:
    """A simulated drive's machine settings and memory as last saved."""

    profile: Profile
    unit: int
    state_file: Path
    settings: dict[str, float | int]
    pending_power_cycle: list[str]  # codes whose new value waits for a power cycle
    eeprom_writes: int
    running: RunningSummary | None  # None: just powered on (nothing running to carry over)
    missing: tuple[str, ...] = ()  # entries the drive lacks (answered with exception 02)


def effective_values(profile: Profile, unit: int, entries: list[Entry]) -> list[int]:
    """The raw values the drive's control uses (a power-cycle parameter reads back its new value before then)."""
    bank = RegisterBank.open(profile, unit)
    return [bank.effective_value(e.code) for e in entries]


def status(profile: Profile, unit: int) -> SimStatus:
    return _status(SimulatedDrive(profile, unit))


def configure(profile: Profile, unit: int, **changes: float | int | None) -> SimStatus:
    """Change the simulated machine's true properties (None: unchanged); UsageError for a value out of range."""
    drive = SimulatedDrive(profile, unit)
    drive.configure(**{k: v for k, v in changes.items() if v is not None})
    return _status(drive)


def set_missing(profile: Profile, unit: int, codes: list[str]) -> SimStatus:
    """Make the simulated drive lack these entries (exception 02 for them); [] restores all. UsageError for an
    unknown code."""
    drive = SimulatedDrive(profile, unit)
    drive.set_missing(codes)
    return _status(drive)


def power_cycle(profile: Profile, unit: int) -> list[str]:
    """Switch the drive off and on; returns the codes whose pending change took effect."""
    return SimulatedDrive(profile, unit).power_cycle()


def factory_reset(profile: Profile, unit: int) -> Path:
    """Erase the drive's state (factory defaults, no history); returns the state file that held it."""
    path = state_path(profile.id, unit)
    path.unlink(missing_ok=True)
    return path


def _status(drive: SimulatedDrive) -> SimStatus:
    bank = drive.bank
    assert bank.path is not None
    return SimStatus(
        profile=drive.profile,
        unit=drive.unit,
        state_file=bank.path,
        settings=dict(drive.settings),
        pending_power_cycle=bank.pending_power_cycle(),
        eeprom_writes=bank.eeprom_writes,
        running=running_summary(bank.extra),
        missing=tuple(drive.missing),
    )
