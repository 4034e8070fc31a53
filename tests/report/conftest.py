"""One tune on virtual time shared by the report tests (it is the slow part)."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink
from servotool.tuning.tune import TuneRequest, tune_inertia


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """(profile, TuneResult) of a dsx7e at load ratio 3 tuned with gains and a step check, on virtual time."""
    pytest.importorskip("matplotlib")
    mp = pytest.MonkeyPatch()
    mp.setenv("SERVOTOOL_SIM_DIR", str(tmp_path_factory.mktemp("sim")))
    profile = load_profile("dsx7e")
    clock = VirtualClock(100.0)
    sim_drive = build_drive(profile, 1, clock, persist=False)
    sim_drive.settings.update(load_ratio=3.0, friction=0.05)
    sim_drive.firmware.reconfigure()
    drive = Drive(VirtualLink([sim_drive], clock), profile, 1)
    res = tune_inertia(drive, TuneRequest(gains=True, rigidity=12, step_check=True, max_speed=600), clock=clock)
    mp.undo()
    return profile, res
