"""The drive's tuning functions in the simulated loop: a notch passes its depth at its centre and the rest, friction
compensation adds its torque by the speed reference's direction, and both come from the profile's parameters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servotool.clock import VirtualClock
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.loop_functions import FrictionFeedForward, Notch, NotchSetting
from servotool.sim.plant import TS


def _amplitude(setting: NotchSetting, hz: float) -> float:
    notch = Notch(setting, TS)
    t = np.arange(int(1.0 / TS)) * TS
    y = np.array([notch.step(math.sin(2 * math.pi * hz * x)) for x in t])
    return float(np.max(np.abs(y[y.size // 2 :])))


def test_a_notch_passes_its_depth_at_its_centre_and_leaves_the_rest():
    assert _amplitude(NotchSetting(80.0, 5, 0), 80.0) < 0.01
    assert _amplitude(NotchSetting(80.0, 5, 50), 80.0) == pytest.approx(0.5, abs=0.02)
    assert _amplitude(NotchSetting(80.0, 5, 0), 400.0) > 0.95
    assert not NotchSetting(4000.0, 2, 0).active(TS)  # IS620P's default: at the control rate's Nyquist, inert
    assert not NotchSetting(80.0, 0, 0).active(TS) and not NotchSetting(80.0, 2, 100).active(TS)


def test_friction_compensation_by_the_references_direction():
    ff = FrictionFeedForward(offset_pct=1.0, coulomb_fwd_pct=5.0, coulomb_rev_pct=4.0, viscous_fwd_pct=3.0)
    assert ff.torque_pct(300.0, 3000.0) == pytest.approx(1.0 + 5.0 + 0.3)
    assert ff.torque_pct(-300.0, 3000.0) == pytest.approx(1.0 - 4.0)
    assert ff.torque_pct(0.2, 3000.0) == pytest.approx(1.0)


def test_the_drive_parameters_set_the_loops_functions():
    clock = VirtualClock(10.0)
    sim = build_drive(load_profile("is620p"), 1, clock, persist=False)
    assert sim.firmware.plant.gains.notches[0].hz == 4000.0
    for code, raw in (("H09-12", 120), ("H09-13", 4), ("H09-14", 10)):
        sim.bank.apply_parameter(sim.profile.entry(code), raw)
        sim.firmware._param_changed(sim, sim.profile.entry(code), raw)
    assert sim.firmware.plant.gains.notches[0] == NotchSetting(120.0, 4.0, 10.0)
    dsx = build_drive(load_profile("dsx7e"), 1, clock, persist=False)
    entry = dsx.profile.entry("Pn121")
    dsx.bank.apply_parameter(entry, 55)
    dsx.firmware._param_changed(dsx, entry, 55)
    assert dsx.firmware.plant.gains.friction_ff.coulomb_fwd_pct == pytest.approx(5.5)


def test_sd25s_factory_notches_pass_everything():
    """SD25's manual leaves the sense of a notch's depth open (Po219, default 0): read as the cut, the factory
    notches (2000 Hz, width 5, depth 0) leave the loop as it was."""
    sim = build_drive(load_profile("sd25"), 1, VirtualClock(10.0), persist=False)
    assert sim.firmware.plant.gains.notches and all(n.depth_level == 100.0 for n in sim.firmware.plant.gains.notches)
    assert not any(n.active(TS) for n in sim.firmware.plant.gains.notches)
