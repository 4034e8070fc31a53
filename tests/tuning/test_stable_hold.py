"""The position hold of identification on IS620P's segment route stays damped whatever the load (issue 16 item 3);
a short seeded sample of bench/hold_stability.py, which sweeps every route over loads 0-50."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

from servotool.drive import Drive
from servotool.ops.params import write_one
from servotool.tuning.control.gains import LoopGains
from servotool.tuning.control.margins import least_damping
from servotool.tuning.fit import estimate_inertia
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.stable_hold import HOLD_MIN_DAMPING, StableHold, guarded_jogger
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.test_tune_robustness import set_up

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from hold_stability import GROWTH, run_once

JM = 0.26e-4  # IS620P profile's rotor, kg m^2
FACTORY = LoopGains(25.0, 31.83, 40.0, 0.79)  # H08-00, H08-01, H08-02, H07-05


def test_the_factory_hold_grows_beyond_a_load_of_16_at_the_factory_ratio():
    """The model behind the fix agrees with what issue 16 saw: damped at 10, growing at 37 and 49."""
    at = {r: least_damping(FACTORY, JM * (1 + r), JM * 2.0) for r in (0.0, 10.0, 20.0, 37.0, 49.0)}
    assert at[0.0] > 0.5 and at[10.0] > 0.05
    assert at[20.0] < 0 and at[37.0] < 0 and at[49.0] < 0
    assert least_damping(FACTORY, JM * 50, JM * 2.0, position=False) > 0  # the speed loop alone is stable


def _drive(profile_id: str, baud: int = 115200, **machine: float):
    d = set_up(profile_id, baud, **machine)[1]
    d.dead_man_waived = False  # the hold is tested on the drive's own route
    return d


def _raws(d: Drive, codes: tuple[str, ...]) -> list[int]:
    return [r.raw for r in d.read_entries([d.profile.entry(c) for c in codes])]


HOLD_CODES = ("H08-15", "H08-01", "H08-02")


def test_before_the_pilot_the_hold_is_damped_for_any_load_the_ratio_parameter_holds(sim_dir):
    d = _drive("is620p")
    saved: dict[str, int] = {}
    hold = StableHold(d, "segment", saved)
    before = _raws(d, HOLD_CODES)
    setting = hold.before_pilot()
    assert setting is not None and hold.heaviest() == pytest.approx(120.0)
    gains = LoopGains(25.0, setting.integral_ms, setting.position_per_s, 0.79)
    for load in (0.0, 1.0, 5.0, 20.0, 50.0, 120.0):
        assert least_damping(gains, JM * (1 + load), JM * (1 + setting.ratio)) >= HOLD_MIN_DAMPING - 1e-9, load
    assert setting.ratio > 1.0 and setting.position_per_s < 40.0  # a stiffer speed loop, a softer hold
    assert _raws(d, HOLD_CODES) != before  # written to the drive ...
    assert saved == {c: r for c, r in zip(HOLD_CODES, before, strict=True) if c in saved} and len(saved) >= 2


def test_after_the_pilot_the_estimate_is_the_ratio_and_the_drives_own_hold_comes_back(sim_dir):
    d = _drive("is620p")
    saved: dict[str, int] = {}
    hold = StableHold(d, "segment", saved)
    hold.before_pilot()
    est = _estimate(37.0)
    setting = hold.after_pilot(est)
    assert setting is not None and setting.ratio == pytest.approx(est.load_ratio, abs=0.01)
    assert (setting.integral_ms, setting.position_per_s) == (31.83, 40.0)
    assert _raws(d, HOLD_CODES) == [round(est.load_ratio * 100), 3183, 400]
    assert hold.after_pilot(None) is None  # no estimate: nothing changes


def _estimate(load: float):
    """A clean log of a motor with this load ratio (triangular speed moves forward and back), fitted."""
    j = JM * (1 + load)
    t, v, q = [], [], []
    for k in range(800):
        time = k * 0.005
        phase, sign = time % 0.4, 1.0 if time % 0.8 < 0.4 else -1.0
        accel = 300.0 if phase < 0.1 else -300.0 if phase < 0.2 else 0.0  # rad/s^2
        speed = 300.0 * min(phase, max(0.0, 0.2 - phase)) if phase < 0.2 else 0.0
        t.append(time)
        v.append(sign * speed * 30 / math.pi + 0.1 * math.sin(7.0 * k))  # a little "noise"
        q.append(sign * j * accel / 1.27 * 100 + 0.05 * math.cos(5.0 * k))
    est = estimate_inertia(t, v, q, rated_torque_nm=1.27, rotor_inertia_kgcm2=0.26, torque_limit_pct=300.0)
    assert math.isfinite(est.load_ratio)
    return est


def test_a_noisy_pilot_on_a_bare_motor_does_not_become_the_ratio(sim_dir):
    """30 % friction and 1 % noise on a bare motor: a pilot fit that accepted small speed changes gave a ratio of
    811 with a 'usable' uncertainty, and the drive at that ratio ended in the overload alarm."""
    run = run_once("is620p", 0.0, 0.3, 0.01, 79, baud=57600)
    assert run.outcome in ("ok", "refused") and run.peak < GROWTH, run.reason


def test_a_route_without_a_position_hold_is_left_alone(sim_dir):
    d = _drive("dsx7e")
    hold = StableHold(d, "trigger", {})
    assert not hold.active and hold.before_pilot() is None and hold.after_pilot(_estimate(5.0)) is None


@pytest.mark.parametrize(
    ("profile_id", "load", "friction", "seed"),
    [("is620p", 43.0, 0.1, 3), ("is620p", 50.0, 0.1, 2), ("is620p", 20.0, 0.3, 5), ("sdc", 50.0, 0.1, 1)],
)
def test_a_seeded_sample_of_the_sweep_neither_swings_nor_trips(sim_dir, profile_id, load, friction, seed):
    """Without the stable hold the first swung to 1.7x the planned speed and the second ran into the travel guard."""
    run = run_once(profile_id, load, friction, 0.002, seed, baud=57600 if profile_id == "is620p" else 115200)
    assert run.outcome == "ok", run.reason
    assert run.peak < GROWTH


def test_the_step_check_before_tuning_shows_the_slow_loop_without_the_hold_swinging_up(sim_dir):
    """IS620P at load 37 and the factory ratio: the step check before identification used to end in the overload
    alarm (the hold after the step swung up to 2000 rpm); now it shows the loop as it is and the tune goes on."""
    d = _drive("is620p", 57600, load_ratio=37.0, friction=0.02, noise=0.002, seed=1)
    sim = d.link.drives[1]
    gains = _raws(d, ("H08-00", "H08-01", "H08-02"))
    peak = [0.0]
    sim.on_read.append(lambda _d: peak.__setitem__(0, max(peak[0], abs(sim.firmware.plant.true_speed_rpm))))
    res = tune_inertia(d, TuneRequest(step_check=True), clock=d.link.clock)
    assert res.step_before is not None and res.step_before.failure() is not None  # the slow loop, seen
    assert res.step_after is not None and res.step_after.failure() is None  # ... and fixed by the ratio
    assert peak[0] < 1.3 * res.identified.plan.speed_rpm
    assert _raws(d, ("H08-00", "H08-01", "H08-02")) == gains and res.ratio == pytest.approx(37.0, rel=0.05)


def test_a_jog_on_a_heavy_load_stops_without_swinging_up_and_leaves_the_gains(sim_dir):
    """A 100 rpm JOG of IS620P at load 37 and the factory ratio swung up to 1250 rpm after its stop (the position
    hold); guarded, only the slow speed loop's own overshoot is left."""
    d = _drive("is620p", 57600, load_ratio=37.0, friction=0.02, noise=0.002, seed=1)
    sim = d.link.drives[1]
    gains = _raws(d, HOLD_CODES)
    peak = [0.0]
    sim.on_read.append(lambda _d: peak.__setitem__(0, max(peak[0], abs(sim.firmware.plant.true_speed_rpm))))
    jogger = guarded_jogger(d, d.link.clock)
    jogger.run(jogger.plan(100.0, 1.0))
    assert peak[0] < 200.0 and sim.firmware.plant.alarm is None
    assert _raws(d, HOLD_CODES) == gains


def test_a_ratio_configured_far_above_a_bare_motor_comes_down_for_the_identification(sim_dir):
    """H08-15 = 30 on an unloaded motor: the speed loop at 31x its bandwidth ended the identification in the
    overload alarm; the pilot now runs at a ratio an unloaded motor stands, and 30 is put back (a dry run)."""
    d = _drive("is620p", 57600, load_ratio=0.0, friction=0.02, noise=0.002, seed=1)
    write_one(d, d.profile.entry("H08-15"), 3000)
    try:
        res = tune_inertia(d, TuneRequest(dry_run=True), clock=d.link.clock)
        assert res.ratio == pytest.approx(0.0, abs=0.1)
    except IdentificationRefused as exc:
        # A bare rotor's acceleration torque is little more than the torque reading's 1 % step at this line
        # rate: refused as too uncertain (issue 16 item 1), but never by an alarm. With dithered accelerations the
        # step error shows as a spread between moves (subsets, jackknife) rather than as the fixed floor.
        assert "too uncertain" in str(exc)
    assert d.link.drives[1].firmware.plant.alarm is None
    assert _raws(d, ("H08-15",)) == [3000]
