"""The rigid-model checks (tuning.fit.checks) on the benches' own rows: no false resonance on a rigid load at a
slow line, and the off-model rows that were accepted outside their 3 sigma now covered or refused (issue 16)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from servotool.sim.virtual import HostStalls
from servotool.tuning.fit.subsets import unblamed
from servotool.tuning.identify import IdentificationRefused

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from inertia_accuracy import identify_once
from off_model import identify


@pytest.mark.parametrize(
    "profile_id,baud,ratio,friction,viscous,gravity,noise,seed",
    [
        ("sd25", 19200, 10.0, 0.1, 0.001, -0.4, 0.0, 10),  # bench --profiles --quick, SD25 19200 row, machine 9
        # SDC 19200 row, machine 10 (machine 11, seed 12, crosses the 2-sigma spring hint at 2.6 % since PN29 is read
        # per 1000 rpm as its manual says: its ramps round to whole ms three times coarser, every sample shifts)
        ("sdc", 19200, 10.0, 0.01, 0.0, 0.0, 0.01, 11),
    ],
)
def test_a_rigid_load_on_a_slow_line_is_not_refused_for_a_resonance(
    sim_dir, profile_id, baud, ratio, friction, viscous, gravity, noise, seed
):
    """These were refused 'inertia too uncertain (2.1-2.5 %): perhaps a resonance near 41-43 Hz' although the
    plant is rigid: the spring term's hint fired at half a sigma, and its column is the shape of the integration's
    own curvature correction. Now accepted, with the truth inside the stated 3 sigma and no off-model note, or (the
    SD25 machine since the stop guard foresees host stalls: its moves are a little shorter) refused as too uncertain
    without blaming a resonance."""
    try:
        run = identify_once(ratio, friction, gravity, noise, baud, seed=seed, profile_id=profile_id, viscous=viscous)
    except IdentificationRefused as exc:
        assert "too uncertain" in str(exc) and "resonance" not in str(exc), str(exc)
        return
    est = run.identified.estimate
    assert est is not None and est.ok
    assert abs(run.ratio - ratio) <= 3 * est.ratio_std
    assert not any(n.startswith("off-model:") for n in est.notes), est.notes


@pytest.mark.parametrize(
    "machine,baud,seed",
    [
        ({"backlash_rad": 0.05}, 19200, 8),  # was flagged +4.24 % vs 3 sigma 2.43 %
        ({"resonance_hz": 100.0, "resonance_damping": 0.05}, 19200, 22),  # was accepted +1.36 % vs 3 sigma 1.02 %
        (
            {"resonance_hz": 100.0, "resonance_damping": 0.05},
            115200,
            54,
        ),  # without the unresolved spring: +1.08 vs 0.95
    ],
)
def test_the_off_model_rows_once_outside_their_3_sigma_are_covered_or_refused(sim_dir, machine, baud, seed):
    """bench/off_model.py's violations (ratio 10, the bench's seeds): backlash looked like a load varying over the
    travel and that model moved J the wrong way; a stiff coupling's term was too weak to see. At 115200 the two-mass
    scan covers this coupling's own resonance (100 Hz motor-side at ratio 10: 30 Hz, below its 60 Hz) and finds
    nothing: only the unresolved spring share keeps the truth inside 3 sigma (with it 1.08 % vs 1.58 %)."""
    outcome, est, why = identify(10.0, machine, baud, seed=seed)
    assert outcome in ("accepted", "flagged", "refused"), why
    if outcome != "refused":
        assert est is not None
        assert abs(est.load_ratio - 10.0) <= 3 * est.ratio_std, (outcome, est.load_ratio, est.ratio_std, why)


@pytest.mark.parametrize(
    "profile_id,baud,ratio,friction,viscous,gravity,noise,seed",
    [
        ("sd25", 19200, 10.0, 0.05, 0.0, 0.2, 0.005, 11),  # SD25 19200 row, machine 10
        ("is620p", 19200, 10.0, 0.01, 0.0, 0.0, 0.01, 14),  # IS620P 19200 row, machine 11 with another noise seed
        # (its own seed, 12, is accepted within 3 sigma since a move's own segment ends it: longer moves)
    ],
)
def test_a_rigid_load_too_uncertain_anyway_is_not_blamed_on_a_resonance(
    sim_dir, profile_id, baud, ratio, friction, viscous, gravity, noise, seed
):
    """Refused 'perhaps a resonance near N Hz (a compliant coupling)' on a rigid plant whose fit was too uncertain
    before the spring hint (or with the hint below 2 sigma): the refusal now gives the usual remedy instead, or (at
    the travel the line needs, named after the pilot and followed) the result is within its 3 sigma."""
    try:
        run = identify_once(ratio, friction, gravity, noise, baud, seed=seed, profile_id=profile_id, viscous=viscous)
    except IdentificationRefused as caught:
        reason = str(caught)
        assert "too uncertain" in reason and "resonance" not in reason, reason
        return
    est = run.identified.estimate
    assert est is not None and abs(run.ratio - ratio) <= 3 * est.ratio_std


@pytest.mark.parametrize("seed", [1, 4])
def test_a_damped_two_mass_at_a_fast_line_is_refused_for_its_resonance(sim_dir, seed):
    """A 20 Hz coupling with damping 0.2 at ratio 2 and 115200 baud was accepted +7.2..7.5 % off with a stated
    3 sigma of 4.5-5.1 %: the rigid fit took the load's lag behind the motor for inertia, and the quasi-static spring
    term put the resonance at 45-66 Hz at 2 sigmas. The two-mass model finds it near 20 Hz; what it changes is too
    uncertain to accept, so the refusal names the resonance (or the truth lies within the stated 3 sigma)."""
    outcome, est, why = identify(2.0, {"resonance_hz": 20.0, "resonance_damping": 0.2}, 115200, seed=seed)
    assert est is not None, why
    if outcome == "refused":
        hz = re.search(r"resonance near (\d+) Hz", why)
        assert hz is not None and 15 <= int(hz.group(1)) <= 25, why
    else:
        assert abs(est.load_ratio - 2.0) <= 3 * est.ratio_std, (outcome, est.load_ratio, est.ratio_std, why)


def test_a_rigid_load_whose_travel_differs_by_1_percent_at_a_fast_line_is_not_called_off_model(sim_dir):
    """At 921600 baud (the simulated drive's own rate) thousands of windows make a 1 % difference in J over the
    travel stand 1.5 sigmas out; the result said "off-model: the load varies over the travel". A difference within
    3 % of J now widens the uncertainty without blaming the mechanics."""
    run = identify_once(5.0, 0.05, 0.0, 0.002, 921600, seed=6, profile_id="dsx7e", viscous=0.0)
    est = run.identified.estimate
    assert not any(n.startswith("off-model:") for n in est.notes), est.notes
    assert abs(run.ratio - 5.0) <= 3 * est.ratio_std
    # The note's words for such a grouping (the machine showed them at 2 rev and 1080 rpm; at the 12 rev DSX7E's
    # watchdog run-on now needs for that speed, its travel subsets agree).
    assert unblamed("over the travel (start, middle, end)") == "too little to point to the mechanics"


# Words that blame a coupling the plant does not have.
SPRING_WORDS = ("resonance", "coupling", "torque ripple")


@pytest.mark.parametrize(
    "profile_id,baud,travel,ratio,friction,viscous,gravity,noise,seed",
    [
        # bench --realtime --quick --machines 6, the heavy noise-free machine: refused (virtual time) or accepted
        # -8.3 % (real time) "resonance or torque ripple near 135 Hz": a speed read in whole rpm at 27-95 rpm peaks
        # erred as much as noise the fit did not count (J 6 % low), and the spring term took up the misfit
        ("dsx7e", 115200, 2.0, 50.0, 0.1, 0.001, 0.0, 0.0, 3),
        ("dsx7e", 115200, 2.0, 10.0, 0.1, 0.001, -0.4, 0.0, 10),  # accepted -2 % "near 115 Hz", 2.9 sigma low
        # SDC 9600 (20 samples/s): refused "near 16 Hz" (above the 10 Hz the log resolves), "perhaps near 12 Hz":
        # the torque noise in the samples the spring column shares with the torque integral gave it a spring's sign
        ("sdc", 9600, None, 10.0, 0.05, 0.0, 0.2, 0.005, 11),
        ("sdc", 9600, None, 5.0, 0.01, 0.0005, 0.0, 0.005, 23),
        ("sdc", 9600, None, 10.0, 0.01, 0.0, -0.4, 0.005, 18),  # refused "perhaps a resonance near 16 Hz"
        ("is620p", 57600, None, 1.0, 0.01, 0.001, -0.4, 0.005, 41),  # accepted, "off-model: ... near 48 Hz"
        ("dsx7e", 19200, None, 1.0, 0.2, 0.0005, -0.4, 0.01, 60),  # accepted 3 % low, "off-model: ... near 17 Hz"
    ],
)
def test_a_rigid_load_is_not_named_a_resonance_and_its_truth_lies_within_3_sigma(
    sim_dir, profile_id, baud, travel, ratio, friction, viscous, gravity, noise, seed
):
    """The simulated plant is rigid (no resonance_hz): no word of a coupling, accepted with the truth inside the
    stated 3 sigma."""
    run = identify_once(
        ratio, friction, gravity, noise, baud, seed=seed, profile_id=profile_id, viscous=viscous, travel_rev=travel
    )
    est = run.identified.estimate
    assert est is not None and est.ok
    assert not any(w in n for n in est.notes for w in SPRING_WORDS), est.notes
    assert abs(run.ratio - ratio) <= 3 * est.ratio_std, (run.ratio, est.ratio_std)


@pytest.mark.parametrize("seed", [3, 9, 10])
def test_a_heavy_rigid_load_is_not_widened_for_a_coupling_so_soft_the_two_mass_scan_would_have_seen_it(sim_dir, seed):
    """DSX7E 115200, a load of 37 with 20 % Coulomb and 20 % gravity, 1 % noise, servotool's 12 rev: the fit alone
    was 1.3-1.7 % uncertain, and the spring check's share (a free spring term's 1-sigma range) widened it to 3.6-4.2 %
    and refused it: that range reached couplings whose load resonates below 60 Hz, which the two-mass scan searches
    and would have found. Counted only up to the softest coupling the scan leaves unsearched, it is accepted within 3
    sigma at the travel servotool chose (seeds 1-40: accepted 24 -> 37, each new one within 3 sigma)."""
    run = identify_once(37.0, 0.2, 0.2, 0.01, 115200, seed=seed, profile_id="dsx7e", viscous=0.0005)
    est = run.identified.estimate
    assert est is not None and est.ok and est.ratio_std / 38.0 <= 0.02
    assert abs(run.ratio - 37.0) <= 3 * est.ratio_std, (run.ratio, est.ratio_std)


def test_a_light_rigid_load_on_a_slow_line_refused_too_uncertain_names_no_resonance_and_a_travel_that_works(sim_dir):
    """SDC 9600, ratio 1, 0.5 % noise: refused "too uncertain (9.1 %): resonance or torque ripple near 3 Hz", with
    no travel offered. Now the refusal names what falls short and a travel; followed, the truth lies within 3 sigma."""
    machine = (1.0, 0.01, -0.4, 0.005)
    with pytest.raises(IdentificationRefused) as caught:
        identify_once(*machine, 9600, seed=41, profile_id="sdc", viscous=0.001)
    assert "too uncertain" in str(caught.value)
    assert not any(w in str(caught.value) for w in SPRING_WORDS), str(caught.value)
    assert caught.value.remedy is not None
    run = identify_once(
        *machine, 9600, seed=41, profile_id="sdc", viscous=0.001, travel_rev=caught.value.remedy.suggested_rev
    )
    est = run.identified.estimate
    assert not any(w in n for n in est.notes for w in SPRING_WORDS), est.notes
    assert abs(run.ratio - 1.0) <= 3 * est.ratio_std


def test_a_spring_term_of_the_other_sign_within_a_sigma_still_counts_what_it_cannot_rule_out(sim_dir):
    """SDC 9600, a load of 37 with 20 % Coulomb and 20 % gravity, 1 % noise, at the 2 rev allowed and about 20
    samples/s (each request 4 ms late, as real time is): a free spring term's sign is insignificant there, and only
    the spring's sign widened J by what a coupling stiffer than the two-mass scan searches could add. In real time
    12 runs of the bench's machine split on that sign: half refused for the share, the rest accepted on the fit
    alone, one at -5.35 % against a stated 0.92 % (5.8 sigma). Seed 9 came out at +0.2 sigma and was accepted 2.9 %
    high on its fit alone; it now counts the share a spring within a sigma leaves plausible, and is refused so."""
    stalls = HostStalls(rate=1.0, min_s=0.004, max_s=0.004, seed=9)
    with pytest.raises(IdentificationRefused) as caught:
        identify_once(37.0, 0.2, -0.2, 0.01, 9600, seed=9, profile_id="sdc", stalls=stalls, follow=False)
    said = str(caught.value)
    assert "from the fit itself, the rest what the model checks cannot rule out at this sampling" in said, said
    assert not any(w in said for w in SPRING_WORDS), said
