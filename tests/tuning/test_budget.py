"""What the line needs, said before the first move (issue 31 item 4): the travel and time for the 2 % target from the
measured sample rate, the torque limits and the travel allowed."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from servotool.tuning import budget, planning
from servotool.tuning.errors import TravelNeeded, TuneDeclined
from servotool.tuning.planning import MotionPlan
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.test_tune_robustness import set_up

# A small servo motor's figures (DSX7E's rotor and rated torque) read in 0.1 % steps, 120 ms ramps.
LINE = budget.Line(
    samples_per_s=300.0,
    torque_step_pct=0.1,
    torque_noise_pct=0.2,
    speed_noise_rpm=0.5,
    rotor_kgm2=1.7e-5,
    rated_nm=0.64,
    speed_cap_rpm=3000.0,
    torque_limit_pct=300.0,
    ramp_s=0.12,
)
SLOW = replace(LINE, samples_per_s=60.0, torque_step_pct=1.0, ramp_s=0.2)  # 7.5 rev and about 29 s for the motor


def test_a_slower_line_needs_more_travel_and_a_heavier_load_less():
    fast = budget.need(LINE, 0.0, 0.02)
    slow = budget.need(SLOW, 0.0, 0.02)
    assert fast.reachable and slow.reachable and slow.travel_rev > fast.travel_rev
    heavy = budget.need(LINE, 10.0, 0.02)
    assert heavy.reachable and heavy.travel_rev <= fast.travel_rev
    assert budget.MIN_TIME_S <= fast.time_s <= budget.MAX_TIME_S


def test_the_travel_allowed_is_said_with_the_loads_it_serves():
    needs = budget.needs(SLOW, 1.0, 0.02)
    assert not needs.enough and needs.lightest.travel_rev > 1.0
    said = needs.words()
    assert f"needs {needs.lightest.travel_rev:g} rev of travel and about" in said and "60 samples/s" in said
    if needs.from_ratio is not None:
        assert f"1 rev serve load ratios from {needs.from_ratio:g}" in said
    assert budget.needs(LINE, needs.lightest.travel_rev + 1.0, 0.02).enough


def test_a_line_that_cannot_reach_the_target_says_so_with_what_came_closest():
    hopeless = replace(LINE, samples_per_s=5.0, torque_step_pct=1.0, torque_noise_pct=2.0, ramp_s=0.5)
    found = budget.need(hopeless, 0.0, 0.02)
    assert not found.reachable and found.sigma_rel > 0.02
    assert "cannot reach 2 %" in found.words(0.02)


def test_the_acceleration_torque_is_a_share_of_the_drives_limit():
    assert budget.torque_cap_pct(300.0) == budget.TORQUE_SHARE * 300.0
    assert budget.torque_cap_pct(None) == budget.torque_cap_pct(budget.DEFAULT_LIMIT_PCT)


def test_the_needs_are_said_before_anything_moves_and_a_travel_is_asked_for_once(sim_dir):
    """SDC at its factory 9600 baud (24 samples/s), a light load: the line's needs (the motor alone: 13 rev, about
    29 s) reach the caller before the motion, the axis still where it was; the caller is asked once for a travel,
    and the one it gives is the travel the motion is planned with."""
    sim, d, clock = set_up("sdc", 9600, load_ratio=1.0, friction=0.02, noise=0.002, seed=2)
    start = sim.firmware.plant.theta
    asked, approved = [], []

    def choose(needs: budget.Needs) -> float | None:
        asked.append((needs, sim.firmware.plant.theta))
        return needs.lightest.travel_rev if needs.lightest.reachable else None

    def approve(motion) -> bool:
        approved.append((motion, sim.firmware.plant.theta))
        return False  # nothing moves: the needs and the travel are what is tested

    with pytest.raises(TuneDeclined):
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock, choose_travel=choose, approve_motion=approve)
    assert len(asked) == 1 and asked[0][1] == start
    needs = asked[0][0]
    assert not needs.enough and needs.lightest.reachable and needs.line.samples_per_s < 30.0
    assert needs.lightest.travel_rev <= 20.0 and needs.lightest.time_s <= 30.0  # issue 31 item 5's SDC 9600 row
    motion, theta = approved[0]
    assert theta == start and motion.travel_limit_rev == needs.lightest.travel_rev
    assert motion.needs is not None and motion.needs.enough
    assert motion.time_limit_s == motion.needs.most_s  # said before moving, and held to


def test_the_most_a_run_takes_is_said_before_moving_and_no_budget_grows_past_it():
    """The needs line said "the motor alone needs 3.5 rev and about 9 s" and the run went on over the 2 rev allowed
    for 13.6 s (IS620P 57600, real time; SDC 13.4 s, DSX7E 26.8 s): that was the motor alone's time at the travel
    it needs, not the run's. A short travel's run may take MAX_TIME_S (time buys the precision); one whose travel
    serves every load twice the time named (a late host's lost samples): said before moving, and the plan's budget,
    the pilot's or an extension's, stops there."""
    short = budget.needs(SLOW, 1.0, 0.02)
    assert not short.enough and short.most_s == budget.MAX_TIME_S
    assert f"the run takes at most {budget.MAX_TIME_S:.0f} s" in short.words()
    served = budget.needs(LINE, 12.0, 0.02)
    assert served.enough and served.most_s == budget.LATE_TIME_FACTOR * max(budget.MIN_TIME_S, served.lightest.time_s)
    assert served.most_s < budget.MAX_TIME_S and f"the run takes at most {served.most_s:.0f} s" in served.words()
    plan = MotionPlan(1000.0, 0.12, (1, -1), 20, 12.0, adaptive=True, needs=served, time_limit_s=served.most_s)
    assert plan.budgeted(budget.MAX_TIME_S).time_budget_s == served.most_s
    assert plan.budgeted(0.0).time_budget_s == planning.TIME_BUDGET_S


def test_a_run_on_that_lowers_the_speed_needs_more_travel():
    """A dead host's run-on bounds the speed in proportion to the travel (planning.fit_run_on): the budget plans with
    the speed the motion will have, not the one the travel alone would allow (DSX7E at 2 rev moved at about 180 rpm
    where the budget assumed 1080, and every noisy machine was refused after the motion with no travel named)."""
    noisy = replace(LINE, speed_noise_rpm=10.0)
    free = budget.need(noisy, 0.0, 0.02)
    bound = budget.need(replace(noisy, speed_share=0.17), 0.0, 0.02)
    assert free.reachable and bound.reachable
    assert bound.travel_rev >= 2 * free.travel_rev
    # the speed at a travel is the share of what the travel alone allows
    assert budget.predicted(replace(noisy, speed_share=0.5), 0.0, 2.0, 10)[1] == pytest.approx(
        0.5 * budget.predicted(noisy, 0.0, 2.0, 10)[1]
    )


def test_the_excitation_counts_only_what_clears_the_zero_speed_band():
    """The fit's windows stay out of a zero-speed band of three speed noises: a ramp's speed change below it is no
    excitation, so a noisier reading needs a faster move."""
    quiet, noisy = replace(LINE, speed_noise_rpm=1.0), replace(LINE, speed_noise_rpm=10.0)
    assert budget.excitation(quiet, 300.0) > 10 * budget.excitation(noisy, 300.0)
    assert budget.excitation(noisy, 3 * 10.0 * 1.0001 / (1 - 2 / (300.0 * budget.MOTION_SHARE * 0.12))) > 0
    assert budget.excitation(replace(LINE, speed_noise_rpm=0.0), 300.0) == float("inf")


def test_a_speed_read_in_steps_is_as_noisy_as_the_fit_counts_it():
    """A noise-free speed read in whole rpm reads steady at rest, yet its rounding is noise in every speed change the
    fit sees (step / sqrt 12): the excitation the budget predicts counts it as the fit does."""
    steady = replace(LINE, speed_noise_rpm=0.0, speed_step_rpm=1.0)
    assert budget.excitation(steady, 300.0) == pytest.approx(
        budget.excitation(replace(LINE, speed_noise_rpm=12**-0.5), 300.0)
    )
    assert budget.excitation(replace(steady, speed_noise_rpm=2.0), 300.0) == budget.excitation(
        replace(LINE, speed_noise_rpm=2.0), 300.0
    )


def test_a_refusal_for_too_little_excitation_names_the_travel_that_clears_it():
    """No fit stood (speed changes 7x the noise, 10x needed): the travel named is the least whose moves, scaled to the
    excitation this run showed, clear the limit; a run that showed more needs less."""
    noisy = replace(LINE, speed_noise_rpm=10.0, speed_share=0.17)
    nan = float("nan")
    weak = budget.more_travel(noisy, 0.0, 2.0, 10, nan, 0.02, excitation_seen=3.0)
    better = budget.more_travel(noisy, 0.0, 2.0, 10, nan, 0.02, excitation_seen=7.0)
    assert weak is not None and better is not None
    assert weak.travel_rev > better.travel_rev > 2.0
    assert budget.more_travel(noisy, 0.0, 2.0, 10, nan, 0.02) is None  # nothing seen: nothing to scale


def test_a_noisy_drive_at_its_default_travel_is_told_the_travel_before_moving_and_identifies_with_it(sim_dir):
    """DSX7E at 115200 and its 2 rev default, 1 % speed noise (10 rpm): the watchdog's run-on keeps the moves near
    180 rpm, too little against the noise; the travel the line needs is named before anything moves, and followed,
    the result is within its 3 sigma and that travel."""
    machine = {"load_ratio": 10.0, "friction": 0.3, "viscous": 0.0005, "load_torque": -0.2, "noise": 0.01, "seed": 2}
    sim, d, clock = set_up("dsx7e", 115200, **machine)
    start = sim.firmware.plant.theta
    with pytest.raises(TravelNeeded) as named:
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    assert not named.value.moved and sim.firmware.plant.theta == start
    travel = named.value.travel_rev
    assert 2.0 < travel <= 20.0 and f"--travel {travel:g}" in str(named.value)
    _sim, d, clock = set_up("dsx7e", 115200, **machine)
    res = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=travel), clock=clock)
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 10.0) <= 3 * est.ratio_std
    assert res.identified.travel_used_rev <= travel


def test_where_no_travel_serves_the_motor_alone_the_lightest_load_one_serves_is_named():
    """SDC at 9600 with 1 % noise: no travel serves the motor alone (3.9 % at best, the moves bound by the rated
    speed), and a run whose 2 rev served no load was refused before moving naming no travel at all, although heavier
    loads identify at 15 rev. The needs name the lightest load some travel serves, and its travel."""
    sdc = budget.Line(
        samples_per_s=24.0,
        torque_step_pct=1.0,
        torque_noise_pct=1.0,
        speed_noise_rpm=10.0,
        rotor_kgm2=1.2e-4,
        rated_nm=2.39,
        speed_cap_rpm=3000.0,
        torque_limit_pct=None,
        ramp_s=0.29,
    )
    needs = budget.needs(sdc, 2.0, 0.02)
    assert not needs.lightest.reachable and not needs.enough
    named = needs.named
    assert named is not None and named.reachable and named.load_ratio > 0 and 2.0 < named.travel_rev <= 20.0
    assert f"a load ratio of {named.load_ratio:.2g} needs {named.travel_rev:g} rev" in needs.words()


def test_a_run_that_did_better_than_the_model_is_named_a_shorter_travel_but_no_less_than_the_best_measured():
    """The model's efficiency is a cautious one (EFFICIENCY); a run whose uncertainty came out below the model's is
    scaled down to what it showed, as far as the best the bench measured (BEST_EFFICIENCY): SDC 9600's motor alone
    was named no travel at all where 5.5-11 rev identify it."""
    slow = replace(SLOW, speed_noise_rpm=2.0)
    model = budget.predicted(slow, 0.0, 2.0, 20, floor=False)[0]  # a run's uncertainty with the step floor taken out
    as_model = budget.more_travel(slow, 0.0, 2.0, 20, model, 0.02)
    better = budget.more_travel(slow, 0.0, 2.0, 20, 0.5 * model, 0.02)
    best = budget.more_travel(slow, 0.0, 2.0, 20, budget.BEST_EFFICIENCY / budget.EFFICIENCY * model, 0.02)
    beyond = budget.more_travel(slow, 0.0, 2.0, 20, 0.01 * model, 0.02)
    assert as_model is not None and better is not None and best is not None and beyond is not None
    assert best.travel_rev <= better.travel_rev < as_model.travel_rev
    assert beyond.travel_rev == best.travel_rev  # no further than the best measured


def test_the_torque_cap_grows_the_acceleration_alone_with_the_speed() -> None:
    """A pilot at 750 rpm peaking at 72 % of rated, 2 % of it the acceleration's (the rest friction and gravity):
    scaled whole, 180 % of a 300 % limit allows 1875 rpm; the acceleration alone reaches it far beyond, and the
    friction and gravity leave the acceleration no more than the limit's rest."""
    whole = 750.0 * budget.torque_cap_pct(300.0) / 72.0
    assert budget.torque_speed_cap(750.0, 72.0, 2.0, 300.0) == pytest.approx(750.0 * budget.torque_cap_pct(300.0) / 2.0)
    assert budget.torque_speed_cap(750.0, 250.0, 2.0, 300.0) == pytest.approx(750.0 * 52.0 / 2.0)
    assert budget.torque_speed_cap(750.0, 72.0, 72.0, 300.0) == pytest.approx(whole)  # all of it the acceleration's
    assert budget.torque_speed_cap(750.0, 299.0, 2.0, 300.0) >= 750.0 * budget.torque_cap_pct(300.0) / 299.0
    assert budget.torque_speed_cap(750.0, 0.0, 0.0, 300.0) == math.inf


def test_the_strongest_travel_is_the_least_at_which_the_drive_bounds_the_moves() -> None:
    """What a refusal names where a model check widened the fit (tuning.identify): the least travel at which the
    torque or the speed the drive allows bounds the moves, and none where they bound them already."""
    strongest = budget.strongest_travel(LINE, 37.0, 2.0, 0.02)
    assert strongest is not None and strongest.bound == "torque" and not strongest.reachable
    assert budget.predicted(LINE, 37.0, strongest.travel_rev - 0.5, 20)[2] == "travel"
    assert budget.strongest_travel(LINE, 37.0, strongest.travel_rev, 0.02) is None
