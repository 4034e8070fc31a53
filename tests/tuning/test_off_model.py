"""Identification on mechanics outside the rigid model (issue 16 item 4): right, flagged or refused in words."""

from __future__ import annotations

import numpy as np
import pytest

from bench.inertia_accuracy import bench_travel
from servotool.tuning.fit.signals import reading_step
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.realtime_cli import STALL_WORDS, near, tune_json
from tests.tuning.test_tune_robustness import set_up

OFF_MODEL_WORDS = ("load varies over the travel", "inertia differs", "resonance", "lost motion")
# An accepted result further off than the rigid loads' worst target (issue 16: 3 %) must say why; closer, the truth
# inside its stated 3 sigma is what the issue asks (backlash 0.05 rad comes out +0.8..2.2 % with a 3 sigma of 2.8-3 %).
WORST_RIGID = 0.03
# Backlash through the CLI: J 35 % low and refused as not fitting until the windows where the motor turns alone were
# left out; a loaded host that starves the sampling (--port sim: 1700-2300 samples/s at load 4-5) may still leave
# too few clear windows, and the refusal then names backlash, the load's own mechanics.
NOT_FITTED = ("model does not fit the data", "backlash")
STARVED_HZ = 1000.0


def _outcome(sim, d, clock):
    """('accepted', estimate) or ('refused', reason), within the bench's travel (DSX7E: room for its watchdog's
    run-on)."""
    try:
        res = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=bench_travel(d.profile.id)), clock=clock)
    except IdentificationRefused as exc:
        return "refused", str(exc)
    return "accepted", res.identified.estimate


def test_an_arm_on_a_gear_is_fitted_with_a_load_that_varies_over_the_travel(sim_dir):
    """The constant-load model put J 14 % off with a 1 % uncertainty; now the load varies with position in the fit,
    the result says so, and the truth is inside the stated 3 sigma."""
    sim, d, clock = set_up(
        "dsx7e", 19200, load_ratio=5.0, friction=0.02, noise=0.002, seed=6, arm_gravity=0.1, gear=10.0
    )
    outcome, est = _outcome(sim, d, clock)
    assert outcome == "accepted", est
    assert any("load varies over the travel" in n for n in est.notes)
    assert abs(est.load_ratio - 5.0) <= 3 * est.ratio_std


@pytest.mark.parametrize("seed", [3, 6])
def test_an_arm_whose_gravity_changes_little_over_a_short_travel_is_not_accepted_outside_its_3_sigma(
    sim_dir, monkeypatch, seed
):
    """DSX7E at 115200 baud over the 2 rev the CLI allows (its moves slowed to 183 rpm by the dead-man's run-on, 0.35
    rev): an arm of 10 % through a gear of 10 turns 13 degrees, and where its load's change came out under 2 % of
    rated torque the rigid fit stood: accepted 6.8 and 5.7 % low against a stated 3 sigma of 2.9 and 4.2 %, with no
    note (seeds 3 and 6; the bench's own runs use 12 rev, and real time through the CLI found it: -6.55 %, 7.4
    sigma). A significant load term too small to name now widens J by what it would change: refused, or the truth
    within 3 sigma."""
    import bench.off_model as off_model

    monkeypatch.setattr(off_model, "bench_travel", lambda _profile: 2.0)
    outcome, err, sig3, why = off_model.outcome_of(5.0, {"arm_gravity": 0.1, "gear": 10.0}, 115200, seed, "dsx7e")
    assert outcome == "refused" or abs(err) <= sig3, (outcome, err, sig3, why)
    assert "sign convention" not in why and "backlash" not in why, why


@pytest.mark.parametrize("seed", [1, 2])
def test_an_arm_at_a_heavy_load_whose_term_the_fit_cannot_call_significant_still_moves_j(sim_dir, seed):
    """DSX7E at 115200 baud over the CLI's 2 rev, its moves shortened to 0.35 rev by the dead-man's run-on: an arm of
    10 % through a gear of 10 at a load ratio of 20 was accepted 3.0 and 4.2 % low at 3.1 and 4.5 sigma with no note
    (seeds 1 and 2; 8 of 10 seeds outside 3 sigma; real time through the CLI -3.56 %, 5.4 sigma). Every move
    accelerates forward near home and backward at the far end, and the load term, below 4 sigma, was left out while
    it moved J by several of its sigmas. J now comes from the model with the term beyond 2 sigma: the truth within
    3 sigma."""
    _sim, d, clock = set_up(
        "dsx7e", 115200, load_ratio=20.0, friction=0.02, noise=0.002, seed=seed, arm_gravity=0.1, gear=10.0
    )
    d.dead_man_waived = False  # as the CLI runs it
    est = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=2.0), clock=clock).identified.estimate
    assert abs(est.load_ratio - 20.0) <= 3 * est.ratio_std, (est.load_ratio, est.ratio_std, est.notes)


@pytest.mark.parametrize(
    "machine",
    [
        {"arm_gravity": 0.4, "gear": 10.0, "arm_angle": 30.0, "seed": 7},
        {"backlash_rad": 0.05, "seed": 4},
        {"resonance_hz": 20.0, "seed": 3},  # was accepted 15-24 % off with a 1 % uncertainty
        {"resonance_hz": 50.0, "seed": 12, "load_ratio": 10.0},
        # Backlash 0.1 rad on a light load: accepted +7.9 and +8.9 % off with a stated 3 sigma of 5.8 and 6.3 % (7 of
        # 14 accepted runs of bench/off_model.py's machine outside their 3 sigma) until J was compared across weak,
        # medium and strong accelerations (the motor crosses the gap alone where the torque reverses)
        {"backlash_rad": 0.1, "seed": 9, "load_ratio": 2.0},
        {"backlash_rad": 0.1, "seed": 10, "load_ratio": 2.0},
    ],
)
def test_an_off_model_load_is_refused_or_flagged_in_words_never_wrong_and_tight(sim_dir, machine):
    machine = {"load_ratio": 5.0, **machine}
    ratio = machine["load_ratio"]
    sim, d, clock = set_up("dsx7e", 19200, friction=0.02, noise=0.002, **machine)
    outcome, found = _outcome(sim, d, clock)
    if outcome == "refused":
        assert any(w in found for w in OFF_MODEL_WORDS), found
    else:
        assert abs(found.load_ratio - ratio) <= 3 * found.ratio_std, found
        if abs(found.load_ratio - ratio) > WORST_RIGID * (1 + ratio):
            assert any(n.startswith("off-model:") for n in found.notes)


def test_a_rigid_load_gets_no_off_model_note(sim_dir):
    sim, d, clock = set_up("dsx7e", 19200, load_ratio=5.0, friction=0.02, noise=0.002, seed=3)
    outcome, est = _outcome(sim, d, clock)
    assert outcome == "accepted" and not any(n.startswith("off-model:") for n in est.notes)


# Words that blame the mechanics: a rigid load's refusal or notes must not carry them.
MECHANICS_WORDS = ("backlash", "lost motion", "resonance", "coupling", "off-model")


@pytest.mark.parametrize(
    "baud,ratio,noise,seed",
    [
        # 115200 baud, 0.2 % noise: "off-model: ... backlash or a compliant coupling" (16 of 24 rigid runs), then
        # widened "as much as the speed noise alone can make it differ" (23 of 24 at 12 rev); now 6 of 24 are
        # widened, by what their weakest accelerations show (1.5-3 %), and none blames the mechanics
        (115200, 1.0, 0.002, 2),
        (115200, 5.0, 0.002, 3),
        (115200, 5.0, 0.002, 9),
        (115200, 1.0, 0.002, 8),
        (115200, 1.0, 0.002, 10),
        # 19200 baud, 1 % noise, 6 rev: refused "inertia differs with the acceleration (weak, medium, strong) by
        # 7-8 % (3.1-3.3x its uncertainty) ... backlash" (seeds 2 and 11 of 1-12, and widened in 5 more)
        (19200, 5.0, 0.01, 2),
        (19200, 5.0, 0.01, 11),
        # seed 4 was refused too uncertain (2.8 %) at 6 rev and named 11; since a pilot that cannot tell the load
        # lets the motion go on with the longest budget, it identifies at 6 rev (seeds 1-8: all within 2 sigma)
        (19200, 5.0, 0.01, 4),
    ],
)
def test_speed_noise_is_not_sorted_with_the_acceleration_into_backlash_on_a_rigid_load(
    sim_dir, baud, ratio, noise, seed
):
    """Windows sorted by their own speed change sorted its noise too: a window whose noise shrank it landed among
    the weak ones and read J high, one whose noise grew it among the strong ones and read J low (+3..+6 % and
    -2..-5 % in every run at 1 % noise, more sigmas the longer the log), and the accelerations' disagreement was
    blamed on backlash. They are now sorted by the speed change read just outside each window, whose noise is not
    theirs, and each third's J is corrected for the speed noise as the whole fit is: the truth within 3 sigma, and
    no word of mechanics the load does not have."""
    _sim, d, clock = set_up("dsx7e", baud, load_ratio=ratio, friction=0.05, noise=noise, seed=seed)
    travel = 6.0 if baud == 19200 else bench_travel("dsx7e")
    est = tune_inertia(d, TuneRequest(dry_run=True, travel_rev=travel), clock=clock).identified.estimate
    assert not any(w in n for n in est.notes for w in MECHANICS_WORDS), est.notes
    assert abs(est.load_ratio - ratio) <= 3 * est.ratio_std


def test_through_the_cli_an_arm_load_is_flagged_or_refused_with_its_reason(cli):
    """Real time, judged as a loaded CI holds it (realtime_cli): flagged when accepted, else refused in words; the
    3 sigma judgement of this machine is test_an_arm_on_a_gear_is_fitted_with_a_load_that_varies_over_the_travel's,
    on virtual time."""
    assert (
        cli("sim", "config", "--load-ratio", "5", "--arm-gravity", "0.15", "--gear", "10", "--friction", "0.02").code
        == 0
    )
    r, data = tune_json(cli, "--port", "sim", "tune", "inertia", "--yes", "--dry-run", "--travel", "12")
    if r.code == 0:
        assert near(data, 5.0), data
        if abs(data["ratio"] - 5.0) > WORST_RIGID * 6.0:  # further off than a rigid load: says why (the load, or
            # the host's stalls it saw in the log: a loaded host alone biases a real-time run by a few %)
            said = (*OFF_MODEL_WORDS, *STALL_WORDS)
            assert any(w in n for n in data["notes"] for w in said), (data["ratio"], data["notes"])


def test_through_the_cli_backlash_is_identified_clear_of_its_lost_motion_and_flagged(cli):
    """--port sim (about 2000 samples/s idle), backlash 0.1 rad at ratio 2: refused as "model does not fit the data"
    with J 35 % low (1.30-1.36) until the windows where the motor may turn alone were left out; now J comes within
    1 % and the result says why it was fitted that way. Real time, judged as a loaded CI holds it (realtime_cli): a
    loaded host samples at 165-380 samples/s (two CPU burners beside two test workers), where the crossings weigh
    too little to flag (accepted 1.3 % low, no note) or its stalls' gaps are what the fit left out (named); the flag
    is asked for where the run sampled as an idle host does, without a stall; a refusal as not fitting only where
    the host starved the sampling. The judgement a loaded host cannot make here is made on virtual time, with and
    without seeded stalls: test_host_latency's test_backlash_is_fitted_clear_of_its_lost_motion_..."""
    assert cli("sim", "config", "--load-ratio", "2", "--backlash-rad", "0.1", "--friction", "0.02").code == 0
    args = ("--port", "sim", "tune", "inertia", "--yes", "--dry-run", "--travel", "12")
    r, data = tune_json(cli, *args, honest=NOT_FITTED)
    rate = (data.get("sample_rate") or {}).get("value")
    if r.code == 1:  # refused in words that name their cause (assert_said); as not fitting only on a starved host
        if NOT_FITTED[0] in data["reason"]:  # (the old failure, on an idle one)
            assert rate is not None and rate < STARVED_HZ, f"{data['reason']} at {rate} samples/s"
        return
    assert near(data, 2.0), data
    stalled = any(w in n for n in data["notes"] for w in STALL_WORDS)
    if rate is not None and rate >= STARVED_HZ and not stalled:
        assert any(n.startswith("off-model: lost motion") for n in data["notes"]), (rate, data["notes"])


def test_a_torque_read_in_whole_percent_does_not_pass_for_backlash(sim_dir):
    """bench --profiles IS620P 57600, machine 38 (a bare motor, noise-free readings in whole percent): its weak
    accelerations misread by a larger share of a step read J 19 % apart from the strong ones, refused as backlash
    until only windows whose acceleration torque spans 10 steps were sorted by acceleration."""
    from bench.inertia_accuracy import identify_once

    try:
        identify_once(0.0, 0.2, -0.4, 0.0, 57600, seed=39, profile_id="is620p", viscous=0.0)
    except IdentificationRefused as exc:
        assert "acceleration" not in str(exc), exc


def test_the_torque_step_is_found_from_readings_on_a_grid():
    assert reading_step(np.array([3.0, -1.0, 0.0, 7.0, 3.0]) * 0.0127) == pytest.approx(0.0127)
    assert reading_step(np.array([0.1, 0.27, 0.7, 1.31])) == 0.0  # not on one grid
    assert reading_step(np.array([0.5, 0.5])) == 0.0


def _refused_then_followed(machine: dict[str, float], words: str, travel_rev: float) -> str:
    """Refused at travel_rev (DSX7E at 19200) with `words` and a longer travel; at that travel, within its 3 sigma.
    Returns the refusal. (At 2 rev, DSX7E's 500 ms watchdog's run-on keeps the moves at 184 rpm: too little
    acceleration first.)"""
    _sim, d, clock = set_up("dsx7e", 19200, **machine)
    with pytest.raises(IdentificationRefused) as refused:
        tune_inertia(d, TuneRequest(dry_run=True, travel_rev=travel_rev), clock=clock)
    assert words in str(refused.value)
    assert refused.value.remedy is not None, str(refused.value)
    _sim, d, clock = set_up("dsx7e", 19200, **machine)
    est = tune_inertia(
        d, TuneRequest(dry_run=True, travel_rev=refused.value.remedy.suggested_rev), clock=clock
    ).identified.estimate
    assert abs(est.load_ratio - machine["load_ratio"]) <= 3 * est.ratio_std
    return str(refused.value)


@pytest.mark.parametrize("seed", [10, 1010])
def test_backlash_is_fitted_clear_of_its_lost_motion_or_refused_naming_it(sim_dir, seed):
    """IS620P at 57600, backlash 0.2 rad on a light load (bench/off_model.py --profile is620p --baud 57600): where
    the braking torque reverses, the motor crossed the gap alone and those windows, through the friction every
    window shares, pulled J 5 % low in every subset alike; accepted outside its 3 sigma in 3 of 3 runs, no note. The
    windows clear of the lost motion now give J, or the refusal names it."""
    _sim, d, clock = set_up("is620p", 57600, load_ratio=2.0, friction=0.02, noise=0.002, seed=seed, backlash_rad=0.2)
    outcome, found = _outcome(_sim, d, clock)
    if outcome == "refused":
        assert "lost motion (backlash?) where the torque reverses" in found, found
    else:
        assert any("lost motion" in n for n in found.notes), found.notes
        assert abs(found.load_ratio - 2.0) <= 3 * found.ratio_std, found


def test_a_refusal_for_lost_motion_names_a_travel_that_then_identifies(sim_dir):
    """A stronger motion crosses the gap faster: fewer windows are lost to it, and the refusal says how far.
    Backlash 0.1 rad at ratio 2 and 4 rev reads as a 15-17 Hz spring, which took J 3-4 sigma low (8 of seeds 1-12
    accepted so, naming a resonance; the rest refused naming it, and so no travel). The windows clear of lost motion
    put J the other way, so both are named, the uncertainty covers both, and a longer travel is named: 12 of 12
    refused so, and followed, 12 of 12 within their 3 sigma (this seed: --travel 7.5, +2.8 sigma, the worst)."""
    refusal = _refused_then_followed(
        {"load_ratio": 2.0, "friction": 0.02, "noise": 0.002, "seed": 6, "backlash_rad": 0.1},
        "lost motion (backlash?) where the torque reverses",
        4.0,
    )
    assert "too uncertain" in refusal, refusal


AT_ONE_PERCENT = pytest.mark.xfail(
    strict=True,
    reason="issue 31 item 5, open: at 1 % noise SDC 9600's 40 Hz coupling under ratio 37 is accepted 8.5 % high, "
    "3 sigma 4.6 % (1.8x): the windows through torque steps, whose reversals the ringing hides from the kinks",
)


@pytest.mark.parametrize(
    "noise,seed",
    [(0.005, 2), (0.005, 3), (0.01, 2), pytest.param(0.01, 4, marks=AT_ONE_PERCENT)],
)
def test_a_heavy_load_behind_a_stiff_coupling_at_a_slow_line_is_covered_or_refused(sim_dir, noise, seed):
    """SDC at 9600 baud (24 samples/s), a 40 Hz coupling under a load 37 times the motor's (bench/off_model.py's
    heavy rows): at 0.5 % noise it was accepted 8.2 and 9.6 % high with a stated 3 sigma of 3.2 %, 2.6x and 3.0x
    beyond it. The windows through a torque step read J 16-20 % high, those beside one 6-7 %, the rest -1..+3 %: the
    load's ringing raised the torque noise estimate the kinks are judged by (3.2-3.9 %, 0.6 % true) and the
    reversals were no kinks. The spring term saw it (strong, its resonance above the 24 samples/s) and now widens
    it by what it would change: refused, "what the model checks cannot rule out at this sampling". At 1 % noise the
    term is too weak to; seed 2's came out of the other sign within a sigma, which now counts the share a spring
    leaves plausible too. Seed 4 strict: it fails the suite once fixed, to be made plain. Wanted: the truth within
    the stated 3 sigma, or a refusal that blames no arm or load that varies."""
    from bench.off_model import identify

    machine = {"resonance_hz": 40.0, "resonance_damping": 0.05}
    outcome, est, why = identify(37.0, machine, 9600, seed, "sdc", noise=noise)
    if outcome == "refused":
        assert "load varies" not in why and "arm" not in why, why
    else:
        assert outcome in ("accepted", "flagged"), (outcome, why)
        assert abs(est.load_ratio - 37.0) <= 3 * est.ratio_std, (est.load_ratio, est.ratio_std)


def test_a_heavy_load_behind_a_coupling_the_sampling_does_not_resolve_is_not_accepted_outside_its_3_sigma(sim_dir):
    """DSX7E at 19200 baud (65 samples/s), a 60 Hz coupling under a load 37 times the motor's, readings noisy by
    0.5 % (bench/off_model.py's heavy row, its third seed): the spring term was strong (z -7) but put the resonance
    near 68 Hz, above what 65 samples/s resolve, so only its unresolved share (0.6 % of J) counted, and J was
    accepted 6.3 % high with a stated 3 sigma of 2.6 %. What the term would change now widens it, unnamed: the
    truth lies within the stated 3 sigma, or it is refused."""
    from bench.off_model import identify

    machine = {"resonance_hz": 60.0, "resonance_damping": 0.05}
    outcome, est, why = identify(37.0, machine, 19200, 2533, "dsx7e", noise=0.005)
    if outcome == "refused":
        assert "too uncertain" in why, why
    else:
        assert abs(est.load_ratio - 37.0) <= 3 * est.ratio_std, (est.load_ratio, est.ratio_std)


def test_a_negative_inertia_on_a_load_the_checks_find_off_model_blames_no_sign_convention(sim_dir):
    """IS620P 57600 over the CLI's 2 rev, a two-mass load at 10 Hz (bench/off_model.py's, ratio 5): J came out below
    zero and the refusal said "check that torque and speed share a sign convention" (real time through the CLI, and
    here on virtual time). The model checks had found the load off the rigid model: the refusal says so."""
    _sim, d, clock = set_up(
        "is620p", 57600, load_ratio=5.0, friction=0.02, noise=0.002, seed=1, resonance_hz=10.0, resonance_damping=0.05
    )
    with pytest.raises(IdentificationRefused) as refused:
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    said = str(refused.value)
    assert "inertia <= 0" in said and "sign convention" not in said, said
    assert "does not follow the rigid model" in said and any(w in said for w in OFF_MODEL_WORDS), said


def test_a_j_below_the_rotor_on_a_load_the_checks_find_off_model_names_it_and_no_travel(sim_dir):
    """DSX7E 115200 over the CLI's 2 rev, a two-mass load at 10 Hz (ratio 5): J came out at or below zero, and the
    refusal said only "no travel up to 100 rev brings it to 2 % ... (the speed or the torque the drive allows bounds
    the moves)", the mechanics the checks found left to the notes. It now names them and seeks no travel: a stronger
    motion leaves them as they are."""
    _sim, d, clock = set_up(
        "dsx7e", 115200, load_ratio=5.0, friction=0.02, noise=0.002, seed=1, resonance_hz=10.0, resonance_damping=0.05
    )
    with pytest.raises(IdentificationRefused) as refused:
        tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    said = str(refused.value)
    assert "at the rotor's own inertia" in said and any(w in said for w in OFF_MODEL_WORDS), said
    assert "no travel" not in said and refused.value.remedy is None, said
