"""Forced digital inputs (profile key forced_inputs): the forcing switch's values and the trigger's bits.

One reading for the client (motion.forced_inputs) and the simulated drive (sim.firmware), so both agree on what
'forcing on' and 'the JOG bits' are.
"""

from __future__ import annotations

from servotool.model.codec import field_index
from servotool.model.profile import Entry, ForcedInputs, Profile
from servotool.model.roles import jog_codes


def _digit(entry: Entry, spec: ForcedInputs) -> tuple[int, int]:
    """(shift, mask) of the switch's digit (the whole value where none is named)."""
    if not spec.digit:
        return 0, -1
    width = entry.field_width
    return width * field_index(entry, spec.digit), (1 << width) - 1


def is_forcing(profile: Profile, switch_raw: int) -> bool:
    """Whether a raw value of the forcing switch has forcing on."""
    spec = profile.forced_inputs
    assert spec is not None
    shift, mask = _digit(profile.entry(spec.switch_code), spec)
    return (switch_raw >> shift) & mask == spec.on


def switch_value(profile: Profile, switch_raw: int, forcing: bool) -> int:
    """The switch's raw value with forcing on or off, its other digits kept."""
    spec = profile.forced_inputs
    assert spec is not None
    shift, mask = _digit(profile.entry(spec.switch_code), spec)
    value = spec.on if forcing else spec.off
    if mask == -1:
        return value
    return (switch_raw & ~(mask << shift)) | (value << shift)


def trigger_bits(profile: Profile) -> int:
    """The forced levels' bits that carry the JOG trigger (role jog's codes, e.g. DI1 = JOGU, DI2 = JOGD)."""
    jog = profile.role("jog")
    if jog is None:
        return 0
    bits = 0
    for raw in jog_codes(jog).values():
        bits |= raw
    return bits
