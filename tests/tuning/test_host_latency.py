"""Host latency named as such (issue 31 item 3), on virtual time with a seeded host that stalls: a stall that let a
move run past the travel limit, or that left gaps in the log the model checks read as mechanics, is named in the
refusal, never blamed on the loop, a resonance, backlash or a sign convention."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from servotool.sim.virtual import HostStalls
from servotool.tuning.errors import IdentificationFailed, TravelExceeded
from servotool.tuning.fit.signals import paused_within, stall
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.test_tune_robustness import set_up

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from inertia_accuracy import identify_once

# DSX7E at 19200 (about 65 samples/s), a load of 3, moves at 300 rpm; before 2 % of its requests the host stalls
# 60-120 ms (a loaded laptop's scheduler), seeded.
STALLS = {"rate": 0.02, "max_s": 0.12, "min_s": 0.06}
WRONG = ("overshoots", "resonance", "backlash", "sign convention")
# What this line names before moving for the motor alone once a dead host's run-on bounds the speed (at 2 rev the
# watchdog's run-on leaves about 180 rpm; the line's budget says so and stops after the pilot)
TRAVEL_REV = 3.5


def _tune(seed: int):
    _sim, d, clock = set_up(
        "dsx7e", 19200, stalls=HostStalls(seed=seed, **STALLS), load_ratio=3.0, friction=0.02, noise=0.002, seed=seed
    )
    return tune_inertia(d, TuneRequest(dry_run=True, max_speed=300, travel_rev=TRAVEL_REV), clock=clock)


@pytest.mark.parametrize("seed", range(1, 9))
def test_a_host_that_stalls_is_accepted_within_its_3_sigma_or_refused_without_a_wrong_cause(sim_dir, seed):
    """Seeds 1-8 of 60-120 ms stalls before 2 % of the requests: accepted within the stated 3 sigma, or refused (or
    stopped at the travel limit) in words that blame no loop, resonance, backlash or sign convention."""
    try:
        res = _tune(seed)
    except (IdentificationRefused, TravelExceeded) as exc:
        said = str(exc)
        assert not any(w in said for w in WRONG), said
        if isinstance(exc, TravelExceeded):
            assert "the host stalled" in said, said
        return
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 3.0) <= 3 * est.ratio_std
    t, speed, _torque, _position = res.identified.trace.fitted()
    if stall(np.asarray(t), np.asarray(speed))[0] > 0:  # accepted on a log with a stall: says so (seeds 1
        # and 2 were accepted with no note at all)
        assert any("the host stalled" in n for n in est.notes), est.notes


@pytest.mark.parametrize("seed", [2, 3, 4, 5, 11, 14])
def test_a_stall_does_not_carry_a_segment_move_past_the_travel_limit(sim_dir, seed):
    """IS620P at 57600 (the segment route), the bench's under-damped machine 5 (load 37, friction 0.2, gravity -0.2,
    noise 1 %; its moves' own segments ran 0.4 rev past their end), before 2 % of the requests a 50-100 ms stall: a
    stall hid a move's ramp, or delayed the stop that was to cut its segment short of the band, and the segment ran
    on past the 2 rev travel limit (these six seeds; two of six runs in real time with one CPU burner). The segment
    no longer than the band leaves room for, the drive brakes it inside the band itself: each run accepted within
    the stated 3 sigma and the travel."""
    stalls = HostStalls(rate=0.02, max_s=0.1, seed=seed, min_s=0.05)
    run = identify_once(37.0, 0.2, -0.2, 0.01, 57600, seed=5, profile_id="is620p", viscous=0.0005, stalls=stalls)
    est = run.identified.estimate
    assert est is not None and abs(run.ratio - 37.0) <= 3 * est.ratio_std, (run.ratio, est.ratio_std)
    assert run.identified.travel_used_rev is not None and run.identified.travel_used_rev <= 2.0


@pytest.mark.parametrize(
    "stalls",
    [
        HostStalls(0.05, 0.03, 3, 0.002),
        HostStalls(0.05, 0.03, 7, 0.002),
        HostStalls(0.02, 0.34, 1, 0.1),  # issue 31's long stalls
        HostStalls(0.02, 0.34, 2, 0.1),
    ],
)
def test_an_arm_on_a_host_that_stalls_is_never_blamed_on_the_sign_convention_or_backlash(sim_dir, stalls):
    """An arm through a gear at 115200 on a host that stalls: the rigid model the friction is reported from put
    Coulomb friction below zero, noted as "check the torque sign convention" (2-30 ms stalls, seed 3; a sign
    convention would have turned J negative too), and the long stalls were refused as "model does not fit the data:
    backlash, compliance ..." (seeds 1, 2). Accepted or refused, no word blames the sign convention or backlash, and
    the stall or the load is named. A late host's run is given more time (identify: LATE_NAMED), in which the 340 ms
    stalls may come close enough together for DSX7E's watchdog: that stop names the host too."""
    _sim, d, clock = set_up(
        "dsx7e",
        115200,
        stalls=stalls,
        load_ratio=5.0,
        friction=0.02,
        noise=0.002,
        seed=stalls.seed,
        arm_gravity=0.15,
        gear=10.0,
    )
    try:
        est = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=12), clock=clock).identified.estimate
        said = ""
    except IdentificationRefused as exc:
        est, said = exc.result.estimate, str(exc)
    except IdentificationFailed as exc:  # a long stall the drive's watchdog caught (the time a late host is given)
        est, said = None, str(exc)
        assert "host watchdog" in said, said
    text = " ".join([said, *(est.notes if est else ())])
    assert "sign convention" not in text and "backlash" not in text, text
    assert "the host stalled" in text or "load varies over the travel" in text, text


def test_the_same_loads_without_stalls_are_accepted_within_their_3_sigma(sim_dir):
    for seed in (1, 2, 9, 10):
        _sim, d, clock = set_up("dsx7e", 19200, load_ratio=3.0, friction=0.02, noise=0.002, seed=seed)
        res = tune_inertia(d, TuneRequest(dry_run=True, max_speed=300, travel_rev=TRAVEL_REV), clock=clock)
        est = res.identified.estimate
        assert est is not None and abs(res.ratio - 3.0) <= 3 * est.ratio_std


@pytest.mark.parametrize("stalls", [None, HostStalls(0.02, 0.3, 1, 0.1), HostStalls(0.02, 0.3, 2, 0.1)])
def test_backlash_is_fitted_clear_of_its_lost_motion_and_a_host_that_stalls_is_named(sim_dir, stalls):
    """The machine of test_off_model's backlash test through the CLI (DSX7E, backlash 0.1 rad at ratio 2), on virtual
    time: the judgement that run cannot make on a loaded host. Without stalls accepted, flagged as lost motion, the
    truth within its 3 sigma; with 100-300 ms stalls before 2 % of the requests (as a loaded 2-core CI's) accepted
    within 3 sigma and saying why it was fitted that way (the lost motion or the stalls' gaps left out), or refused
    naming the stalls (seed 1: 2.9 % uncertain), never as a model that does not fit."""
    _sim, d, clock = set_up("dsx7e", 115200, stalls=stalls, load_ratio=2.0, backlash_rad=0.1, friction=0.02)
    try:
        res = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=12), clock=clock)
    except IdentificationRefused as exc:
        assert stalls is not None and "the host stalled" in str(exc) and "does not fit" not in str(exc), str(exc)
        return
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 2.0) <= 3 * est.ratio_std, (res.ratio, est.ratio_std)
    flagged = any(n.startswith("off-model: lost motion") for n in est.notes)
    assert flagged or (stalls is not None and any("the host stalled" in n for n in est.notes)), est.notes


def test_a_gap_while_the_axis_moved_is_a_stall_and_one_at_rest_is_not():
    t = np.arange(0.0, 1.0, 0.01)
    rpm = np.where(t < 0.5, 300.0, 0.0)
    assert stall(t, rpm) == (0.0, pytest.approx(0.01))
    moving = np.concatenate([t[:30], t[30:] + 0.2])  # 210 ms between two samples at 300 rpm
    gap, usual = stall(moving, rpm)
    assert gap == pytest.approx(0.21) and usual == pytest.approx(0.01)
    resting = np.concatenate([t[:70], t[70:] + 0.2])  # the same gap with the axis at rest: the fit between moves
    assert stall(resting, rpm)[0] == 0.0
    # The sampler's own pause (a fit between moves) in the gap while the axis moved: only the rest is the host's.
    assert stall(moving, rpm, paused_within(moving, [(0.30, 0.48)]))[0] == 0.0
    assert stall(moving, rpm, paused_within(moving, [(0.30, 0.40)]))[0] == pytest.approx(0.11)


def test_the_fit_between_moves_is_no_host_stall_though_a_ringing_load_moves_in_it(sim_dir):
    """DSX7E 115200, a two-mass load at 20 Hz (bench/off_model.py's), no host stall, each fit between moves taking
    the 100 ms it took on an idle machine through the CLI: the load still rang (38 rpm) when the fit began and paused
    the samples, and the refusal said "sampling gaps of up to 116 ms while the axis moved (… the host stalled, a busy
    machine?)". The pause is servotool's own: the refusal names the resonance instead."""
    _sim, d, clock = set_up(
        "dsx7e", 115200, load_ratio=5.0, friction=0.02, noise=0.002, seed=1, resonance_hz=20.0, resonance_damping=0.05
    )
    clock.computing_s = 0.1
    with pytest.raises(IdentificationRefused) as refused:
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    said = str(refused.value)
    assert "the host stalled" not in said and "resonance near 2" in said, said
