"""Turning an identified inertia into the drive's inertia-ratio and gain parameter values."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.gain_units import from_canonical
from servotool.model.profile import Entry
from servotool.tuning.gains import GainSuggestion, suggest_gains
from servotool.tuning.identify import IdentificationFailed
from servotool.tuning.preflight import FEATURE

GAIN_ROLES = {"speed_loop_gain": "speed_loop_gain_hz", "speed_loop_integral": "speed_integral_ms",
              "position_loop_gain": "position_loop_gain_per_s", "torque_filter": "torque_filter_ms"}


@dataclass(frozen=True)
class GainChange:
    role: str
    entry: Entry
    old: float
    new: float
    raw: int


def gain_changes(drive: Drive, load_ratio: float, *, rigidity: int | None, bandwidth_hz: float | None
                 ) -> tuple[GainSuggestion, list[GainChange]]:
    """Gains for the identified inertia, mapped onto the profile's gain roles (clamped to their ranges)."""
    p = drive.profile
    motor = p.motor
    assert motor is not None
    if rigidity is None and bandwidth_hz is None:
        rig = p.role("rigidity")
        rigidity = int(raw_to_eng(rig, drive.read_entries([rig])[0].raw)) if rig else 13
        rigidity = max(1, min(31, rigidity))
    try:
        sugg = suggest_gains(rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2, load_ratio=max(0.0, load_ratio),
                             rigidity=rigidity, bandwidth_hz=bandwidth_hz)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    entries = [(role, p.role(role)) for role in GAIN_ROLES]
    present = [(role, e) for role, e in entries if e is not None]
    current = drive.read_entries([e for _, e in present])
    changes = []
    for (role, e), reading in zip(present, current, strict=True):
        target = from_canonical(role, e, getattr(sugg, GAIN_ROLES[role]))
        raw = eng_to_raw(e, target)
        changes.append(GainChange(role, e, float(raw_to_eng(e, reading.raw)), float(raw_to_eng(e, raw)), raw))
    return sugg, changes


def ratio_raw(drive: Drive, load_ratio: float) -> tuple[Entry, int]:
    entry = drive.profile.need_role("inertia_ratio", FEATURE)
    raw = eng_to_raw(entry, drive.profile.param_from_load_ratio(max(0.0, load_ratio)), clamp=False)
    if not entry.min <= raw <= entry.max:
        raise IdentificationFailed(f"identified ratio {load_ratio:.2f} does not fit {entry.code}'s range")
    return entry, raw
