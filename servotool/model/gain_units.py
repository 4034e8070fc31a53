"""Loop-gain settings in one set of units, whatever unit a drive prints.

Canonical units: speed loop gain Hz, speed integral ms, position loop gain 1/s, torque filter ms (time constant).
Drives differ: SDC's torque filter (PN50) is a cutoff frequency in Hz; SD25 Po301 and SDC PN5 print no unit and are
read in 0.1/s, the usual panel unit (a simulator and tuning assumption, marked unverified in those profiles).
"""

from __future__ import annotations

import math

from servotool.model.profile import Entry


def to_canonical(role: str, entry: Entry, eng: float) -> float:
    """The drive's engineering value of a gain role in canonical units."""
    if role == "torque_filter" and entry.unit == "Hz":
        return 1000.0 / (2 * math.pi * max(eng, 1e-3))
    if role == "position_loop_gain" and not entry.unit:
        return eng / 10.0
    return eng


def from_canonical(role: str, entry: Entry, value: float) -> float:
    """The drive's engineering value for a canonical gain value (inverse of to_canonical)."""
    if role == "torque_filter" and entry.unit == "Hz":
        return 1000.0 / (2 * math.pi * max(value, 1e-6))
    if role == "position_loop_gain" and not entry.unit:
        return value * 10.0
    return value
