"""Gain switching run and judged (issue 34 item 2): a stiffer second gain while moving kept where it improves the
score, put back where it rings on a resonance, refused where the manual does not describe the conditions. Judged on
virtual time (free of host load); what the drive holds is read from the simulated drive's own parameter bank."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw
from servotool.model.loader import load_profile
from servotool.model.roles import sim_extensions
from servotool.sim.firmware import build_drive
from servotool.sim.loop_functions import GainSelector, GainSwitch
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning import function_run as use
from servotool.tuning import score as scoring

FACTORY = {"Po103": 240, "Po104": 1250, "Po130": 0, "Po131": 100, "Po135": 1000}


def _sd25(gain_hz: float, **machine: float):
    """SD25 on a fast line, its inertia ratio right for the load and its speed loop at gain_hz."""
    p = load_profile("sd25")
    clock = VirtualClock(100.0)
    sim = build_drive(p, 1, clock, persist=False)
    make_motion_setup(sim)
    sim.settings.update(noise=0.0005, **machine)
    sim.firmware.reconfigure()
    d = Drive(VirtualLink([sim], clock, 115200), p, 1)
    d.dead_man_waived = True  # SD25 documents no dead-man; the virtual drive needs no E-stop
    for role, value in (
        ("inertia_ratio", p.param_from_load_ratio(machine["load_ratio"])),
        ("speed_loop_gain", gain_hz),
    ):
        entry = p.role(role)
        d.write_raw(entry, eng_to_raw(entry, value))
    return sim, d, clock


def _held(sim, *codes: str) -> dict[str, int]:
    return {c: sim.bank.effective_value(c) for c in codes}


def test_a_stiffer_gain_while_moving_improves_a_soft_loop_and_is_kept(sim_dir):
    sim, d, clock = _sd25(6.0, load_ratio=3.0)
    motion = scoring.planned(d, scoring.motion_for(2.0))
    trial = use.run_function(d, "gain-switching", motion, 3, factor=2.0, clock=clock)
    assert trial.verdict == "better" and trial.kept, [(x.name, x.verdict) for x in trial.differences]
    figures = {x.name: x for x in trial.differences}
    assert figures["iae"].verdict == "better" and figures["overshoot"].verdict == "better"
    # gain 2 = 12 Hz (0.1 Hz units), integral time twice gain 1's (factory Po102 500 = 50 ms), above 20 rpm
    assert _held(sim, "Po103", "Po104", "Po130", "Po131", "Po135") == {
        "Po103": 120,
        "Po104": 1000,
        "Po130": 2,
        "Po131": 200,
        "Po135": 500,
    }
    assert trial.held["Po130"] == 2.0 and trial.held["Po103"] == 12.0
    assert not sim.firmware.plant.servo_on and sim.firmware.plant.active_gain_set == 1  # at rest: gain 1


def test_gain_switching_that_rings_on_a_resonance_is_put_back(sim_dir):
    sim, d, clock = _sd25(15.0, load_ratio=3.0, resonance_hz=40.0, resonance_damping=0.02)
    motion = scoring.planned(d, scoring.motion_for(2.0))
    trial = use.run_function(d, "gain-switching", motion, 3, factor=2.0, clock=clock)
    assert trial.verdict == "worse" and not trial.kept and "written back" in trial.reason
    assert {x.name: x.verdict for x in trial.differences}["settling"] == "worse"
    assert _held(sim, *FACTORY) == FACTORY
    assert trial.held["Po130"] == 0.0


def test_is620p_gain_switching_is_refused_as_undescribed_and_nothing_is_written(sim_dir):
    p = load_profile("is620p")
    clock = VirtualClock(100.0)
    sim = build_drive(p, 1, clock, persist=False)
    d = Drive(VirtualLink([sim], clock, 57600), p, 1)
    with pytest.raises(UsageError, match=r"UNVERIFIED on IS620P.*H08-09.*not described") as err:
        use.run_function(d, "gain-switching", scoring.motion_for(2.0), 2, clock=clock)
    assert "nothing written" in str(err.value)
    assert sim.bank.effective_value("H08-09") == 0 and not sim.firmware.plant.servo_on
    assert not any("gain switching" in x.what for x in sim_extensions(p))  # nothing simulated there either


def test_the_simulated_switch_acts_on_the_documented_speed_condition_and_is_listed():
    """SD25 Po130 = 2 (L7863): above the switching speed gain 2 at once; below it gain 1 after the delay."""
    sel = GainSelector(GainSwitch("speed", speed_rpm=20.0, delay_s=0.05))
    assert sel.step(10.0, 0.001) == 1 and sel.step(25.0, 0.001) == 2
    assert all(sel.step(5.0, 0.001) == 2 for _ in range(49)) and sel.step(5.0, 0.001) == 1
    assert GainSelector(GainSwitch("gain2")).step(0.0, 0.001) == 2
    assert GainSelector(GainSwitch("di")).step(500.0, 0.001) == 1  # not simulated: gain 1, and said so
    listed = [x for x in sim_extensions(load_profile("sd25")) if "gain switching" in x.what]
    assert listed and "L7851-7869" in listed[0].why and "act as gain 1" in listed[0].why
