"""The drive's tuning functions in the simulated loop: a notch passes its depth at its centre and the rest, friction
compensation adds its torque by the speed reference's direction, and both come from the profile's parameters."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from servotool.clock import VirtualClock
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.loop_functions import FrictionFeedForward, GainSwitch, Notch, NotchSetting
from servotool.sim.mechanics import MechanicsSettings
from servotool.sim.plant import TS, DriveGains, MotorData, Plant, PlantSettings

MOTOR = MotorData(
    rated_torque_nm=1.27, rated_speed_rpm=3000, max_speed_rpm=6000, rotor_inertia_kgcm2=0.62, counts_per_rev=131072
)


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


def _ringing_plant() -> Plant:
    """A two-mass machine under a notch, with gain switching on speed and the vibration watched (adaptive notch)."""
    gains = DriveGains(
        inertia_ratio_configured=2.0,
        notches=(NotchSetting(60.0, 2, 0),),
        gain_switch=GainSwitch("speed", speed_rpm=100.0, delay_s=0.2, speed_gain_hz=80.0, speed_integral_ms=10.0),
    )
    settings = PlantSettings(load_ratio=2.0, mechanics=MechanicsSettings(resonance_hz=60.0, resonance_damping=0.02))
    p = Plant(MOTOR, settings, gains)
    p.watch_vibration = True
    return p


def test_a_handed_over_loop_continues_with_its_notch_gain_set_and_vibration_watch():
    """The next process (a `--port sim` command, sim serve) continues the loop functions where the last one left
    them: mid-ring, the notch's memory, the gain set 2 still held through its delay and the watched vibration."""
    p = _ringing_plant()
    p.set_mode("speed")
    p.set_speed_command(500.0)
    p.advance_to(0.1)
    p.set_speed_command(0.0)
    p.advance_to(0.18)  # braked below the switching speed: gain 2 held for its delay
    assert p.active_gain_set == 2 and p.vibration_pct > 0 and any(p._notches[0].memory)
    q = _ringing_plant()
    q.restore(json.loads(json.dumps(p.state())))  # as the state file carries it
    q.set_speed_command(0.0)
    for t in np.arange(0.185, 0.4, 0.005):
        p.advance_to(t)
        q.advance_to(t)
        assert q.active_gain_set == p.active_gain_set
        assert q.vibration_pct == pytest.approx(p.vibration_pct, rel=1e-9, abs=1e-12)
        assert q.true_speed_rpm == pytest.approx(p.true_speed_rpm, rel=1e-9, abs=1e-9)
    assert p.active_gain_set == 1  # the delay ran out in both


def test_a_stored_notch_memory_that_does_not_fit_is_left_out():
    p = _ringing_plant()
    p.set_mode("speed")
    p.set_speed_command(500.0)
    p.advance_to(0.05)
    state = p.state()
    q = Plant(MOTOR, PlantSettings(load_ratio=2.0), DriveGains())  # no notch here: nothing to recall
    q.restore({**state, "_gain_select": ["x", 1]})
    assert q.theta == p.theta and q._notches == []
    r = _ringing_plant()
    r.restore({**state, "_notches": [[math.inf, 0.0]]})
    assert r._notches[0].memory == [0.0, 0.0]
