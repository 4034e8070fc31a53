"""The inertia-ratio parameter value for an identified ratio."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink
from servotool.tuning.errors import IdentificationFailed
from servotool.tuning.gain_writes import ratio_raw


def test_a_bare_motor_is_written_as_the_lowest_ratio_the_parameter_holds(sim_dir):
    """SD25's Po013 starts at 0.01: a bare motor identified at 0.00 or -0.02 (within its 3 sigma) was refused as
    "does not fit Po013's range" (half the runs at load 0 in bench/hold_stability.py); a value far below is not."""
    profile = load_profile("sd25")
    clock = VirtualClock(100.0)
    d = Drive(VirtualLink([build_drive(profile, 1, clock, persist=False)], clock), profile, 1)
    assert ratio_raw(d, 0.0)[1] == 1
    assert ratio_raw(d, -0.02, std=0.012)[1] == 1
    assert ratio_raw(d, 5.0)[1] == 500
    with pytest.raises(IdentificationFailed, match="does not fit Po013's range"):
        ratio_raw(d, -0.5, std=0.05)
