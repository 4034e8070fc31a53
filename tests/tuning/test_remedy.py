"""A refusal for too little excitation names the remedy that helps (issue 16: "the remedies the refusal suggests did
not help"): a longer travel where the travel bounded the moves, worked out from how far short the data fell."""

from __future__ import annotations

import math
import re

import pytest

from servotool.sim.virtual import HostStalls
from servotool.tuning.errors import IdentificationFailed, TravelNeeded
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.planning import MIN_REMEDY_GAIN, REMEDY_MARGIN, remedy
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.test_tune_robustness import set_up


def test_a_travel_bound_refusal_suggests_a_travel_that_covers_its_shortfall():
    cure = remedy(2.0, 3.0, 300.0, 3000.0, "speed")
    assert cure is not None and cure.enough
    assert cure.suggested_rev == math.ceil(2.0 * 3.0 * REMEDY_MARGIN * 2) / 2  # 10 rev, in half revolutions
    assert cure.gain == pytest.approx(cure.suggested_rev / 2.0)
    assert "--travel 10 " in cure.words() and "usually falls with it" in cure.words()


def test_a_small_shortfall_still_asks_for_a_clear_step():
    cure = remedy(2.0, 1.05, 300.0, 3000.0, "speed")
    assert cure is not None and cure.suggested_rev == 2.0 * MIN_REMEDY_GAIN


def test_where_the_torque_or_speed_limit_stops_short_the_remedy_says_it_may_not_be_enough():
    cure = remedy(2.0, 5.0, 300.0, 1200.0, "torque")  # 4x harder at most
    assert cure is not None and not cure.enough
    assert cure.suggested_rev == 8.0
    assert "torque share of the limit" in cure.words() and "may not be enough" in cure.words()


@pytest.mark.parametrize(
    "shortfall, speed, cap",
    [
        (math.nan, 300.0, 3000.0),  # refused for something more travel does not cure
        (0.9, 300.0, 3000.0),  # not short at all
        (3.0, 2000.0, 3000.0),
    ],
)  # the moves nearly reach the cap already
def test_no_travel_is_suggested_where_it_would_not_help(shortfall, speed, cap):
    assert remedy(2.0, shortfall, speed, cap, "speed") is None


def test_sd25_at_its_factory_9600_baud_names_a_travel_that_then_succeeds(sim_dir):
    """SD25 at 9600 (18 samples/s): a load of 37 with gravity was too uncertain within 2 rev and 9 s (3.8 %). The old
    advice, repeat the motion, could not help. Now the pilot shows what the load needs: a longer time at 2 rev, or
    the motion stops there naming the travel (or, where the pilot misjudged, the refusal after the motion names it);
    followed, the result is within its 3 sigma and that travel."""
    machine = {
        "load_ratio": 37.0,
        "friction": 0.1,
        "viscous": 0.001,
        "load_torque": 0.4,
        "noise": 0.002,
        "seed": 9,
        "brake": 1,
    }
    _sim, d, clock = set_up("sd25", 9600, **machine)
    try:
        res = tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    except IdentificationFailed as refused:
        named = refused
    else:  # the pilot showed the load served by 2 rev in a longer time
        est = res.identified.estimate
        assert est is not None and abs(res.ratio - 37.0) <= 3 * est.ratio_std
        assert res.identified.time_used_s <= res.identified.plan.time_budget_s + 0.5
        return
    if isinstance(named, TravelNeeded):
        travel = named.travel_rev
    else:
        assert isinstance(named, IdentificationRefused) and named.remedy is not None, str(named)
        travel = named.remedy.suggested_rev
    assert travel > 2.0 and re.search(rf"--travel {travel:g}\b", str(named)) and "repeat" not in str(named)
    _sim, d, clock = set_up("sd25", 9600, **machine)
    res = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=travel), clock=clock)
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 37.0) <= 3 * est.ratio_std
    assert res.identified.travel_used_rev <= travel


def test_a_speed_bound_remedy_names_the_speed_limit():
    cure = remedy(2.0, 5.0, 300.0, 900.0, "speed")  # 3x at most: rated speed or --max-speed
    assert cure is not None and not cure.enough and cure.suggested_rev == 6.0
    assert "the speed limit (rated or --max-speed)" in cure.words()


def test_a_refusal_for_too_little_excitation_names_a_travel_that_then_identifies(sim_dir):
    """SDC at 9600 (24 samples/s), 1 % speed noise (10 rpm): at 2 rev the speed changes were 6.6x the noise, 10x
    needed, and the refusal said only "use faster accelerations" (no fit stood, so no uncertainty to scale). It now
    names the travel whose moves clear the limit, scaled to the excitation the run showed; followed, the result is
    accepted within that travel and issue 31's 20 rev."""
    machine = {"load_ratio": 10.0, "friction": 0.3, "viscous": 0.0005, "load_torque": -0.2, "noise": 0.01, "seed": 1}
    _sim, d, clock = set_up("sdc", 9600, brake=1, **machine)
    with pytest.raises(IdentificationRefused) as refused:
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    assert "too little acceleration" in str(refused.value)
    cure = refused.value.remedy
    assert cure is not None and 2.0 < cure.suggested_rev <= 20.0, str(refused.value)
    assert re.search(rf"--travel {cure.suggested_rev:g}\b", str(refused.value))
    _sim, d, clock = set_up("sdc", 9600, brake=1, **machine)
    res = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=cure.suggested_rev), clock=clock)
    est = res.identified.estimate
    # within twice its 3 sigma (issue 31's bound for any accepted result; this one reads +1.9 % at 3.6 sigma: heavy
    # loads on SDC read J high, see bench/inertia_accuracy.py's SDC rows for how often the 3 sigma holds)
    assert est is not None and abs(res.ratio - 10.0) <= 6 * est.ratio_std
    assert res.identified.travel_used_rev <= cure.suggested_rev


def test_a_travel_the_user_gave_is_run_not_asked_again_after_the_pilot(sim_dir, monkeypatch):
    """SDC at 9600, a load of 1 (Coulomb 10 %), 4 rev: the pilot (a quarter of the speed) shows 0.6 +- 0.46 and,
    taking the load two sigmas lighter, names the motor alone's 11 rev. Where servotool chose the travel that stop
    saves a run; where the user gave it (following a travel a refusal named, in the real-time bench: 'named 4 rev,
    then the pilot 11'), it asks a second time. Given, the motion runs and the fit decides: accepted within 3 sigma."""
    from bench import inertia_accuracy as bench

    with monkeypatch.context() as chosen, pytest.raises(TravelNeeded) as named:
        chosen.setattr(bench, "bench_travel", lambda _profile: 4.0)  # servotool's travel, not the user's
        bench.identify_once(1.0, 0.1, 0.0, 0.0, 9600, seed=1, profile_id="sdc", follow=False)
    assert named.value.moved and named.value.travel_rev > 1.5 * 4.0
    given = bench.identify_once(1.0, 0.1, 0.0, 0.0, 9600, seed=1, profile_id="sdc", travel_rev=4.0, follow=False)
    est = given.identified.estimate
    assert abs(est.load_ratio - 1.0) <= 3 * est.ratio_std and given.identified.travel_used_rev <= 4.0


def test_a_pilot_need_within_its_slack_of_the_travel_servotool_chose_goes_on(sim_dir, monkeypatch):
    """SDC at 9600, a load of 1 (Coulomb 10 %), servotool's own 7.5 rev: the pilot names 10 rev for the load it
    shows (two sigmas lighter), within PILOT_SLACK of the 7.5 allowed. A stop to ask for 10 costs the user a run for
    a need the pilot cannot tell that closely: the motion goes on and the fit decides (accepted within 1 sigma in
    5.8 rev; without the slack it stopped and named 10)."""
    from bench import inertia_accuracy as bench

    monkeypatch.setattr(bench, "bench_travel", lambda _profile: 7.5)  # servotool's travel, not the user's
    run = bench.identify_once(1.0, 0.1, 0.0, 0.0, 9600, seed=1, profile_id="sdc", follow=False)
    est = run.identified.estimate
    assert abs(est.load_ratio - 1.0) <= 3 * est.ratio_std and run.identified.travel_used_rev <= 7.5
    with pytest.raises(TravelNeeded) as named:  # the same run with servotool's 6 rev: 10.5 is beyond the slack
        monkeypatch.setattr(bench, "bench_travel", lambda _profile: 6.0)
        bench.identify_once(1.0, 0.1, 0.0, 0.0, 9600, seed=1, profile_id="sdc", follow=False)
    assert named.value.moved and named.value.travel_rev > 1.5 * 6.0


def test_a_refusal_that_a_check_widened_names_the_strongest_motion_and_it_then_identifies(sim_dir):
    """DSX7E 115200, a load of 37 with 20 % Coulomb and 20 % gravity, 1 % noise, servotool's 12 rev: the fit alone
    was 1.3-1.5 % uncertain, and the spring check, which cannot rule out a coupling stiffer than 335 samples/s
    resolve, widened it to 3.6-5.2 % (seed 3 then; since the share counts only couplings the two-mass scan leaves
    unsearched, seed 32). The line's model scaled to that said "no travel up to 100 rev brings it to 2 %", where 16
    rev identified it in 5 of 5 seeds. The refusal says where the uncertainty came from and names the strongest
    motion the drive allows as one that may not be enough; followed, it identifies within 3 sigma."""
    from bench import inertia_accuracy as bench

    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(37.0, 0.2, 0.2, 0.01, 115200, seed=32, profile_id="dsx7e", viscous=0.0005)
    words, cure = str(refused.value), refused.value.remedy
    assert "no travel" not in words and "from the fit itself" in words, words
    assert not any(w in words for w in ("backlash", "resonance", "coupling")), words
    assert cure is not None and not cure.enough and cure.suggested_rev > 12.0, words
    run = bench.identify_once(
        37.0, 0.2, 0.2, 0.01, 115200, seed=32, profile_id="dsx7e", viscous=0.0005, travel_rev=cure.suggested_rev
    )
    est = run.identified.estimate
    assert abs(run.ratio - 37.0) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev


def test_a_heavy_load_with_high_friction_keeps_the_speed_its_pilots_whole_torque_allows(sim_dir):
    """IS620P 57600, a load of 20 with 30 % Coulomb and 20 % gravity (the bench's draw seed 31, machine 27): the
    acceleration's part of the pilot's torque alone would have let the moves run at 1069 rpm where the whole peak
    allowed 666, and a loop that does not know the load yet ran 0.28 rev past its band: "travel limit 2 rev
    reached ... the loop overshoots". Its acceleration torque clears the reading's steps by far, so that speed buys
    the fit nothing: the whole peak caps it, and it is identified within 3 sigma inside the travel."""
    from bench import inertia_accuracy as bench

    run = bench.identify_once(20.0, 0.3, 0.2, 0.005, 57600, seed=27, profile_id="is620p", viscous=0.001)
    est = run.identified.estimate
    assert est.ok and abs(run.ratio - 20.0) <= 3 * est.ratio_std
    assert run.identified.travel_used_rev <= 2.0


def test_a_travel_named_where_the_torque_steps_bound_the_fit_identifies_when_followed(sim_dir):
    """SDC 9600, the motor alone with 30 % Coulomb friction and 40 % gravity (real-time bench, draw seed 47): its
    accelerations take 1-2 % of rated torque, read in 1 % steps that stay put through a move. The budget took the
    steps for noise that averages away and named 7 rev; followed, the fit was refused for the steps' floor ("the
    torque reads in 1 % steps against an acceleration torque of 1.8 %") and named more, twice. The budget now plans
    with the floor (budget.step_floor): the travel it names identifies within 3 sigma."""
    from bench import inertia_accuracy as bench

    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(0.0, 0.3, 0.4, 0.0, 9600, seed=2, profile_id="sdc", viscous=0.0)
    cure = refused.value.remedy
    assert cure is not None and cure.enough, str(refused.value)
    run = bench.identify_once(
        0.0, 0.3, 0.4, 0.0, 9600, seed=2, profile_id="sdc", viscous=0.0, travel_rev=cure.suggested_rev
    )
    est = run.identified.estimate
    assert abs(run.ratio) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev


def test_a_torque_reading_whose_steps_hide_the_acceleration_names_a_travel_that_identifies(sim_dir):
    """SDC's motor alone with 30 % Coulomb friction and 40 % gravity, sampled at the 19-20 readings/s that real time
    reaches on its 9600 baud line (7600 baud on virtual time): its acceleration torque, 0.4 % of rated, reads in 1 %
    steps that hardly move. The refusal once said "non-physical result: check that torque and speed share a sign
    convention" with no remedy; it is too uncertain at the rotor's own inertia, and says so with the reading's
    steps. The travel it named, 26 rev, was refused again when followed, for the steps' floor (2.3 %): the run
    capped its speed at 1900 rpm, scaling the pilot's whole peak torque (friction and gravity with it) as if it all
    grew with the speed, where the budget planned 3000 and predicted the floor with them. The acceleration's part
    alone now grows with the speed (budget.torque_speed_cap): the travel named identifies within 3 sigma."""
    from bench import inertia_accuracy as bench

    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(0.0, 0.3, 0.4, 0.0, 7600, seed=1, profile_id="sdc", viscous=0.0)
    words, cure = str(refused.value), refused.value.remedy
    assert "sign convention" not in words and "too uncertain" in words and "1 % steps" in words, words
    assert cure is not None and cure.suggested_rev <= 21.0, words
    run = bench.identify_once(
        0.0, 0.3, 0.4, 0.0, 7600, seed=1, profile_id="sdc", viscous=0.0, travel_rev=cure.suggested_rev
    )
    est = run.identified.estimate
    assert abs(run.ratio) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev


def _late_sdc(**more: object) -> dict:
    """SDC's bare motor on a 9600 baud line whose host answers every request 10 ms late (19 samples/s)."""
    stalls = HostStalls(rate=1.0, min_s=0.01, max_s=0.01, seed=1)
    return {"seed": 1, "profile_id": "sdc", "viscous": 0.0, "stalls": stalls, **more}


def test_where_only_the_budgets_margin_fails_the_strongest_motion_is_named_and_identifies(sim_dir):
    """The same motor on a 9600 baud line whose host answers every request 10 ms late (19 samples/s): the refusal
    said "no travel up to 100 rev brings it to 2 %" (the budget's best, 1.47 % at the rated speed, misses the 1.4 %
    it aims at), where 20-30 rev given are accepted at 1.7-2.0 %. It names the strongest motion the drive allows,
    as one that may not be enough; followed, it identifies within 3 sigma."""
    from bench import inertia_accuracy as bench

    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(0.0, 0.3, 0.4, 0.0, 9600, **_late_sdc())
    words, cure = str(refused.value), refused.value.remedy
    assert cure is not None and not cure.enough and "may not be enough" in words, words
    run = bench.identify_once(0.0, 0.3, 0.4, 0.0, 9600, travel_rev=cure.suggested_rev, **_late_sdc())
    est = run.identified.estimate
    assert abs(run.ratio) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev


def test_after_the_pilot_the_closest_travel_for_the_lightest_load_not_ruled_out_is_named(sim_dir, monkeypatch):
    """The same late line, servotool's travel 9 rev: the pilot showed 0.055 +- 0.28, no travel reaches the budget's
    margin for the motor alone, and the pilot named 14.5 rev for a load of 0.5, refused when followed (2.1 %, the
    torque reading's floor). It names the motor alone's closest, as one that may not be enough, and that identifies
    within 3 sigma."""
    from bench import inertia_accuracy as bench

    monkeypatch.setattr(bench, "bench_travel", lambda _profile: 9.0)

    with pytest.raises(TravelNeeded) as named:
        bench.identify_once(0.0, 0.3, 0.4, 0.0, 9600, **_late_sdc(follow=False))
    words = str(named.value)
    assert named.value.moved and "the motor alone" in words and "may not be enough" in words, words
    run = bench.identify_once(0.0, 0.3, 0.4, 0.0, 9600, travel_rev=named.value.travel_rev, **_late_sdc(follow=False))
    est = run.identified.estimate
    assert abs(run.ratio) <= 3 * est.ratio_std and run.identified.travel_used_rev <= named.value.travel_rev


def test_moves_the_pilots_torque_capped_name_no_travel_that_would_run_them_again(sim_dir):
    """SDC at 19200, a load of 50 with 10 % Coulomb, 40 % gravity and 3 % noise, 8 rev given: the pilot's torque caps
    the moves at about 670 rpm (2.6 of the 8 rev used), and the fit is refused for too little acceleration. The line's
    budget took the speed to grow with the travel and named 32.5 rev as enough; but the plan's speed is at its limit
    already (2921 of 3000 rpm), so a longer travel's pilot is this one's and caps the moves at the same speed: refused
    again. A remedy is planned at the cap the pilot set where a longer travel runs the same pilot: none is named."""
    from bench import inertia_accuracy as bench

    machine = {"seed": 4, "profile_id": "sdc", "viscous": 0.0}
    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(50.0, 0.1, -0.4, 0.03, 19200, travel_rev=8.0, **machine)
    words = str(refused.value)
    assert "too little acceleration" in words and refused.value.remedy is None and "--travel" not in words, words
    with pytest.raises(IdentificationRefused) as again:
        bench.identify_once(50.0, 0.1, -0.4, 0.03, 19200, travel_rev=32.5, **machine)
    assert again.value.result.travel_used_rev < 8.0, str(again.value)


def _relative(refused: IdentificationRefused) -> float:
    est = refused.result.estimate
    assert est is not None
    return est.j_std_kgm2 / est.j_total_kgm2


def test_where_the_sampling_rate_bounds_what_the_checks_leave_open_no_travel_is_named(sim_dir):
    """SDC at 19200 (47 samples/s), a load of 50 with 10 % Coulomb, 40 % gravity and 3 % noise, 20 rev given: the
    pilot's torque caps the moves at about 670 rpm, and the fit is refused at 6.3 %, 6.1 % of it the share the spring
    check adds for a coupling stiffer than the 9.5 Hz its scan searches at that rate. The refusal named 28 rev, "bound
    by the travel", then 39.5: each refused with the same figures, the same moves at the same cap. It names no travel
    now, and says why and what would help; the 28 rev it named is refused as before."""
    from bench import inertia_accuracy as bench

    machine = {"seed": 4, "profile_id": "sdc", "viscous": 0.0}
    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(50.0, 0.1, -0.4, 0.03, 19200, travel_rev=20.0, **machine)
    words = str(refused.value)
    assert refused.value.remedy is None and "--travel" not in words, words
    assert "no travel cures it" in words and "9.5 Hz" in words and "faster line" in words, words
    with pytest.raises(IdentificationRefused) as again:
        bench.identify_once(50.0, 0.1, -0.4, 0.03, 19200, travel_rev=28.0, **machine)
    assert _relative(again.value) == pytest.approx(_relative(refused.value), rel=0.05)


def test_where_stronger_moves_shorten_the_windows_the_same_share_still_names_a_travel_that_cures(sim_dir):
    """SDC at 9600, a load of 50 with 10 % Coulomb, 40 % gravity and 1 % noise (issue 31's machine), 2 rev: refused at
    4.5 % (seed 3: 5.9 %), most of it the same share, cut at the 4.8 Hz the scan searches at 24 samples/s. But its
    windows are 5 sampling intervals long, stretched for the speed change a window needs; a longer travel's stronger
    moves shorten them, and the share of other windows is another: the travel named (3 rev) identifies within 3
    sigma. (Seed 3 is now refused at 2.5 % for a load term over the travel it cannot rule out, with no such share.)"""
    from bench import inertia_accuracy as bench

    machine = {"seed": 1, "profile_id": "sdc", "viscous": 0.0}
    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(50.0, 0.1, -0.4, 0.01, 9600, **machine)
    cure, est = refused.value.remedy, refused.value.result.estimate
    assert est is not None and est.rate_bound is not None and est.window_intervals > 1, str(refused.value)
    assert cure is not None and cure.enough and cure.suggested_rev > 2.0, str(refused.value)
    run = bench.identify_once(50.0, 0.1, -0.4, 0.01, 9600, travel_rev=cure.suggested_rev, **machine)
    est = run.identified.estimate
    assert abs(run.ratio - 50.0) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev


def test_a_load_term_under_one_step_of_the_torque_reading_does_not_refuse_the_travel_named(sim_dir):
    """SD25 at 9600 (torque read in 1 % steps), a rigid load of 20 with 5 % Coulomb and no noise (the bench's draw
    seed 16, machine 28): its refusal named 3.5 rev, and followed, that run was refused at 2.6 % for "the load may vary
    over the travel (its term at 2.5 sigma, 0.7 % of rated torque)": a term under one step of the reading, whose steps
    fall at the same positions in every cycle. Not taken, the travel named identifies within 3 sigma."""
    from bench import inertia_accuracy as bench

    machine = {"seed": 29, "profile_id": "sd25", "viscous": 0.0}
    with pytest.raises(IdentificationRefused) as refused:
        bench.identify_once(20.0, 0.05, 0.0, 0.0, 9600, **machine)
    cure = refused.value.remedy
    assert cure is not None and cure.enough, str(refused.value)
    run = bench.identify_once(20.0, 0.05, 0.0, 0.0, 9600, travel_rev=cure.suggested_rev, **machine)
    est = run.identified.estimate
    assert abs(run.ratio - 20.0) <= 3 * est.ratio_std and run.identified.travel_used_rev <= cure.suggested_rev
