"""The simulated drive's own protections and digital inputs, read from its parameters as the manuals document them.

By role, so any profile that maps them gets them: a software overtravel fence around a mechanical origin (SD25
Po136-Po145 with So-39, AL-27; L3314-3352), a locked-rotor trip (SD25 So-34/So-40, AL-30), speed-regulator saturation
detection (SDC PN79/PN120, AL-6) and the overload multiple as the torque limit (SDC PN65). Forced inputs (SD25
So-57/So-58, section 7.10.9): while forcing is on, every input level comes from the forced value alone; the input
monitor shows the levels the drive acts on (the forced ones), as the manual's words read (L5249-5253), unless the
simulated machine is configured to show the terminals (`sim config --di-monitor terminals`, the other reading).
"""

from __future__ import annotations

import math

from servotool.model.codec import raw_to_eng
from servotool.model.forcing import is_forcing
from servotool.model.profile import Motor, Profile
from servotool.sim.plant import Protections
from servotool.sim.registers import RegisterBank

# The absolute encoder's multi-turn count at power-on (the plant's position 0). A real absolute encoder keeps its
# count; the simulated one starts here, clear of the 0/65535 wrap (L1875) and inside the factory fence (+-1000 turns
# around origin 0).
ENCODER_START_TURNS = 100
MULTI_TURN = 65536  # a 16-bit multi-turn count: 0..65535, wrapping (SD25 L1875)


def _value(profile: Profile, bank: RegisterBank, role: str) -> float | None:
    entry = profile.role(role)
    return None if entry is None else float(raw_to_eng(entry, bank.effective_value(entry.code)))


def _meaning(profile: Profile, bank: RegisterBank, role: str) -> str | None:
    """The enum name of a role's value (lower case), None where the profile lacks the role."""
    entry = profile.role(role)
    if entry is None:
        return None
    return entry.enum.get(bank.effective_value(entry.code), "").strip().lower()


def encoder_position(motor: Motor, position_rev: float) -> tuple[int, int]:
    """(single-turn counts, multi-turn count) the absolute encoder reads at this plant position."""
    turns_total = ENCODER_START_TURNS + position_rev
    turns = math.floor(turns_total)
    counts = min(motor.counts_per_rev - 1, math.floor((turns_total - turns) * motor.counts_per_rev))
    return counts, turns % MULTI_TURN


def _fence(profile: Profile, bank: RegisterBank, motor: Motor, position_rev: float) -> tuple[float, float, str] | None:
    """The fence in the plant's revolutions, where the profile maps one and it is on."""
    action = _meaning(profile, bank, "fence_action")
    if action not in ("stop", "alarm"):
        return None
    parts = {
        role: _value(profile, bank, role)
        for role in (
            "fence_origin_counts",
            "fence_origin_turns",
            "fence_forward_counts",
            "fence_forward_turns",
            "fence_reverse_counts",
            "fence_reverse_turns",
        )
    }
    if any(v is None for v in parts.values()):
        return None
    cpr = float(motor.counts_per_rev)
    origin = float(parts["fence_origin_turns"] or 0.0) + float(parts["fence_origin_counts"] or 0.0) / cpr
    forward = float(parts["fence_forward_turns"] or 0.0) + float(parts["fence_forward_counts"] or 0.0) / cpr
    reverse = float(parts["fence_reverse_turns"] or 0.0) + float(parts["fence_reverse_counts"] or 0.0) / cpr
    # The encoder's count wraps at 65536 turns: the origin is taken where it lies nearest the axis (a signed
    # difference, unverified: the manual does not relate the range to the wrap).
    here = ENCODER_START_TURNS + position_rev
    origin += MULTI_TURN * round((here - origin) / MULTI_TURN)
    base = origin - ENCODER_START_TURNS
    return base - reverse, base + forward, action


def protections(profile: Profile, bank: RegisterBank, motor: Motor, position_rev: float) -> Protections:
    """The protections the drive's parameters switch on now."""
    locked = None
    if _meaning(profile, bank, "locked_rotor_check") == "on":
        seconds = _value(profile, bank, "locked_rotor_time")
        locked = seconds / 1000.0 if seconds is not None else None
    saturation = None
    if _meaning(profile, bank, "saturation_check") == "detect":
        seconds = _value(profile, bank, "saturation_time")
        saturation = seconds / 1000.0 if seconds is not None and seconds > 0 else None
    return Protections(_fence(profile, bank, motor, position_rev), locked, saturation)


def input_levels(profile: Profile, bank: RegisterBank, terminals: int) -> int:
    """The digital input levels the drive acts on: the forced value while forcing is on, else the terminals."""
    spec = profile.forced_inputs
    if spec is None or not is_forcing(profile, bank.effective_value(spec.switch_code)):
        return terminals
    return bank.effective_value(spec.levels_code)


def input_monitor(profile: Profile, bank: RegisterBank, terminals: int, shows_terminals: bool) -> int:
    """What the input monitor shows: the levels the drive acts on, or (the other reading) always the terminals."""
    return terminals if shows_terminals else input_levels(profile, bank, terminals)
