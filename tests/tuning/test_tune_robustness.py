"""tune inertia on loads and line settings the first version got wrong (issue 16), in-process on virtual time."""

from __future__ import annotations

import math

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive, coalesce_reads
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw
from servotool.model.loader import load_profile
from servotool.ops.params import write_one
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import TURNAROUND_S, HostStalls, VirtualLink, make_motion_setup, wire_time
from servotool.tuning.control.friction import friction_report
from servotool.tuning.errors import IdentificationFailed, MarginRefused, TravelNeeded
from servotool.tuning.gain_search import GainSearchFailed, search_gains
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import GainsRolledBack, TuneRequest, tune_inertia


def set_up(profile_id: str, baud: int = 115200, stalls: HostStalls | None = None, **machine: float):
    """(simulated drive, host Drive, clock) of a drive with its motion setup made, on virtual time."""
    profile = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(**machine)
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    d = Drive(VirtualLink([sim], clock, baud, stalls), profile, 1)
    d.dead_man_waived = True  # SD25 and SDC have no dead-man route (issue 15); these tests are about the estimate
    return sim, d, clock


def tune_as_a_user(profile_id: str, baud: int, **machine: float):
    """tune_inertia (a dry run) on a fresh drive (set_up); where it names the travel the line needs (TravelNeeded:
    before moving, or after the pilot) it runs once more with that travel on a fresh drive, as a user does. Returns
    the result, or raises what the last run raised."""
    _sim, d, clock = set_up(profile_id, baud, **machine)
    try:
        return tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    except TravelNeeded as exc:
        assert math.isfinite(exc.travel_rev) and exc.travel_rev > 2.0, str(exc)
        _sim, d, clock = set_up(profile_id, baud, **machine)
        return tune_inertia(d, TuneRequest(dry_run=True, travel_rev=exc.travel_rev), clock=clock)


IS620P_HOLD = ("H08-15", "H08-01", "H08-02")


@pytest.mark.parametrize("ratio,seed", [(37.0, 2), (49.0, 1)])
def test_is620p_with_a_heavy_load_identifies_instead_of_oscillating_after_the_pilot(sim_dir, ratio, seed):
    """IS620P's segment route ends each move in a position hold: at the factory ratio 1.00 with a load of 37-49 it
    swung with growing amplitude after the pilot until the travel guard stopped it (these seeds did, at 57600).
    The hold is now kept damped, and the ratio and gains it used are put back afterwards."""
    sim, d, clock = set_up("is620p", 57600, load_ratio=ratio, friction=0.02, noise=0.002, seed=seed)
    before = _raws(d, IS620P_HOLD)
    peak = [0.0]
    sim.on_read.append(lambda _d: peak.__setitem__(0, max(peak[0], abs(sim.firmware.plant.true_speed_rpm))))
    res = tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - ratio) <= 3 * est.ratio_std
    assert peak[0] < 1.3 * res.identified.plan.speed_rpm  # no swing beyond the planned speed
    assert _raws(d, IS620P_HOLD) == before  # a dry run leaves the drive as it was


GAIN_CODES = ("Pn101", "Pn102", "Pn100", "Pn128", "Pn003")


def _raws(d, codes=GAIN_CODES) -> list[int]:
    return [r.raw for r in d.read_entries([d.profile.entry(c) for c in codes])]


def test_gains_without_the_margins_are_refused_and_nothing_is_written(sim_dir):
    _sim, d, clock = set_up("dsx7e", load_ratio=3.0, noise=0.002)
    before = _raws(d, (*GAIN_CODES, "Pn004"))
    with pytest.raises(MarginRefused, match=r"rigidity 31 leaves phase margin -\d+°.*highest level that keeps them"):
        tune_inertia(d, TuneRequest(gains=True, rigidity=31), clock=clock)
    assert _raws(d, (*GAIN_CODES, "Pn004")) == before


def test_gains_that_fail_the_step_check_are_rolled_back(sim_dir):
    """Forced past the margins, DSX7E's level 31 oscillates on the simulated drive: the check after writing sees
    it, the previous gains go back, and the use case fails (the CLI exits non-zero)."""
    _sim, d, clock = set_up("dsx7e", load_ratio=3.0, noise=0.002)
    before = _raws(d)
    with pytest.raises(GainsRolledBack, match="previous gains were written back") as failed:
        tune_inertia(d, TuneRequest(gains=True, rigidity=31, force=True, verify=True), clock=clock)
    assert failed.value.exit_code == 1 and failed.value.response is not None
    assert _raws(d) == before


def test_gains_at_a_safe_level_pass_the_step_check_and_stay(sim_dir):
    _sim, d, clock = set_up("dsx7e", load_ratio=3.0, noise=0.002)
    res = tune_inertia(d, TuneRequest(gains=True, rigidity=18, verify=True), clock=clock)
    assert res.verified is not None and res.verified.failure() is None
    assert res.proposal.margins is not None and res.proposal.margins.ok()
    assert _raws(d)[-1] == 18 and res.gains_written  # the drive's own rigidity parameter too


def test_tune_gains_raises_the_level_until_a_step_check_fails_and_backs_off(sim_dir):
    """Drive and user believe a load of 4 on a bare motor: the gains come out 5x too stiff, and a level inside the
    computed margins still overshoots on the machine; the search stops there, backs off one level and keeps that
    level's gains."""
    _sim, d, clock = set_up("dsx7e", load_ratio=0.0, friction=0.02, noise=0.002)
    _believe(d, 4.0)
    res = search_gains(d, clock=clock)  # the drive's own ratio
    failed = [t for t in res.trials if t.failure]
    assert len(failed) == 1 and failed[0] is res.trials[-1]  # stopped at the first failure
    assert [t.level for t in res.trials] == list(range(13, failed[0].level + 1))  # from the drive's own level up
    assert res.chosen == failed[0].level - 2 and "backed off" in res.reason
    assert all(t.margins.ok() for t in res.trials)  # never beyond the margins
    assert _raws(d)[-1] == res.chosen  # Pn003 holds the level kept
    assert _raws(d)[0] == next(c.raw for c in res.changes if c.entry.code == "Pn101")


def test_tune_gains_that_fail_at_the_first_level_put_the_old_gains_back(sim_dir):
    _sim, d, clock = set_up("dsx7e", load_ratio=0.0, friction=0.02, noise=0.002)
    _believe(d, 60.0)
    before = _raws(d)
    with pytest.raises(GainSearchFailed, match="previous gains were written back"):
        search_gains(d, load_ratio=60.0, start=22, clock=clock)
    assert _raws(d) == before


def _believe(d, ratio: float) -> None:
    """The drive's own ratio parameter set to `ratio` (a wrong identification): it scales its gains by that."""
    entry = d.profile.role("inertia_ratio")
    d.write_raw(entry, round(d.profile.param_from_load_ratio(ratio) / entry.scale))


def test_a_given_load_ratio_is_tuned_under_the_ratio_the_drive_holds(sim_dir):
    """tune gains --load-ratio 20 on a drive that holds 1.5: the drive scales its gains by 1.5, so the loop runs
    8x softer than gains computed as if 20 were written, and no level keeps the margins: it says why and what to do."""
    _sim, d, clock = set_up("dsx7e", load_ratio=0.0, friction=0.02, noise=0.002)
    with pytest.raises(UsageError, match=r"under the drive's own ratio 1\.50 \(Pn004\).*write Pn004 = 2100 first"):
        search_gains(d, load_ratio=20.0, clock=clock)


def test_friction_is_reported_in_drive_units_with_the_drives_compensation_entries(sim_dir):
    _sim, d, clock = set_up("sdc", load_ratio=3.0, friction=0.1, viscous=0.0005, noise=0.002)
    res = tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    report = friction_report(d.profile, res.identified.estimate)
    assert report is not None and report.coulomb_pct == pytest.approx(10.0, abs=1.0)
    assert report.viscous_pct_at_rated == pytest.approx(0.0005 * 100 * 2 * math.pi * 50, rel=0.25)  # 15.7 %
    suggested = {s.entry.code: s.value for s in report.settings}
    assert set(suggested) == {"PN137", "PN138", "PN139", "PN140"}
    assert suggested["PN137"] == pytest.approx(report.coulomb_pct, abs=0.1)


def test_a_drive_side_result_fooled_by_friction_is_put_back_and_refused(sim_dir):
    """DSX7E's own identification reads 30 % friction as inertia (9.3 for a load of 5): the host method's check
    catches it before it is kept."""
    _sim, d, clock = set_up("dsx7e", load_ratio=5.0, friction=0.3, noise=0.002)
    before = _raws(d, ("Pn004",))
    with pytest.raises(IdentificationFailed, match=r"implausible against the host measurement (4\.9|5\.0)"):
        tune_inertia(d, TuneRequest(method="drive"), clock=clock)
    assert _raws(d, ("Pn004",)) == before
    _sim, d, clock = set_up("dsx7e", load_ratio=5.0, friction=0.02, noise=0.002)
    assert tune_inertia(d, TuneRequest(method="drive"), clock=clock).ratio == pytest.approx(5.0, rel=0.1)


UNMET_AT_FACTORY = (
    "issue 16 item 1 unmet on SD25 at 9600: speed and torque take two requests under its 10-register "
    "limit (18 samples/s at most) and its torque reads in 1 % steps, while 2 rev of travel allow only a few % of "
    "rated torque; see bench/inertia_accuracy.py --profiles"
)


@pytest.mark.parametrize(
    "profile_id, baud",
    [
        pytest.param("sd25", 9600, marks=pytest.mark.xfail(reason=UNMET_AT_FACTORY, strict=False)),
        ("sd25", 19200),
        ("sdc", 9600),
        ("sdc", 19200),
        ("is620p", 57600),
        ("is620p", 19200),
        ("dsx7e", 115200),
        ("dsx7e", 19200),
    ],
)
def test_identification_at_each_drives_factory_line_speed(sim_dir, profile_id, baud):
    """A load of 20: with a load under about 10 the torque that 2 rev of motion takes on these small rotors is a few
    % of rated, against torque readings in 1 % steps (SD25, SDC, IS620P): refused as too uncertain, honestly
    (bench/inertia_accuracy.py --profiles counts those)."""
    _sim, d, clock = set_up(profile_id, baud, load_ratio=20.0, friction=0.05, noise=0.002, seed=3)
    res = tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 20.0) <= 3 * est.ratio_std
    assert res.identified.travel_used_rev <= 2.0 and res.seconds <= 12.0


@pytest.mark.parametrize("profile_id, baud", [("sd25", 9600), ("sdc", 9600), ("dsx7e", 115200)])
def test_identification_samples_at_the_pace_the_line_carries(sim_dir, profile_id, baud):
    """Speed and torque in as few requests as the profile allows (SD25: two, its 10-register limit), position and
    beats only as needed: the motion samples at >= 0.8x what the line carries for those requests back to back."""
    p = load_profile(profile_id)
    entries = [p.role("speed_feedback"), p.role("torque_feedback")]
    line = 1.0 / sum(wire_time(3, count, baud) + TURNAROUND_S for _a, count, _g in coalesce_reads(p, entries))
    try:
        ident = tune_as_a_user(profile_id, baud, load_ratio=20.0, friction=0.05, noise=0.002, seed=3).identified
    except IdentificationRefused as exc:  # SD25 at 9600 may refuse (issue 16): the pace is what is tested here
        ident = exc.result
    assert ident.samples_per_s >= 0.8 * line


def test_a_torque_read_in_whole_percent_is_not_trusted_beyond_its_steps(sim_dir):
    """SD25 at 9600 with noise-free readings: the torque read 3 % while accelerating and 0 % while braking in every
    move, and J came out 18 % high with a stated 0.7 %. The repeated step error is now in the uncertainty: the
    result is refused, or its 3 sigma covers the truth."""
    try:
        res = tune_as_a_user("sd25", 9600, load_ratio=10.0, friction=0.01, viscous=0.0005, noise=0.0, seed=6)
    except TravelNeeded:  # the pilot at the travel named cannot tell the load either: more is named, nothing fitted
        return
    except IdentificationRefused as exc:
        # With dithered accelerations the step error shows as a spread between moves (the jackknife's), or as
        # what is left of the floor ("1 % steps"): either way too uncertain.
        assert "too uncertain" in str(exc)
        return
    est = res.identified.estimate
    assert est is not None and abs(res.ratio - 10.0) <= 3 * est.ratio_std


@pytest.mark.parametrize(
    "profile_id, baud, ratio, seed",
    [
        ("dsx7e", 115200, 0.0, 2),
        ("dsx7e", 115200, 0.0, 3),
        ("dsx7e", 115200, 1.0, 2),
        ("dsx7e", 115200, 1.0, 4),
        ("dsx7e", 115200, 10.0, 4),
        ("is620p", 57600, 1.0, 2),
    ],
)  # the last two: in a dithered cycle's short ramp
def test_a_host_that_stalls_does_not_carry_the_axis_past_its_travel(sim_dir, profile_id, baud, ratio, seed):
    """At the automatic speed (DSX7E about 900 rpm: 0.2 rev of margin is 13 ms) on a host that stalls 10-50 ms before
    2 % of its requests: the stop guard foresees a check as late as the longest gap it has seen, and a dithered
    cycle's ramp lasts at least two such gaps (these runs went past the 2 rev and stopped with 'travel limit
    reached'). A result too uncertain for the shortened moves is refused."""
    _sim, d, clock = set_up(profile_id, baud, stalls=HostStalls(0.02, 0.05, seed), load_ratio=ratio, seed=seed)
    try:
        ident = tune_inertia(d, TuneRequest(dry_run=True), clock=clock).identified
    except IdentificationRefused as exc:
        ident = exc.result
    assert ident.travel_used_rev <= 2.0


def test_a_slow_fit_between_moves_does_not_starve_the_drives_watchdog(sim_dir, monkeypatch):
    """tune inertia fits between moves while DSX7E holds with its 500 ms watchdog (Pn620) running, and feeds it at
    the last safe moment (a third of it spare): a fit of 0.3 s (the two-mass scan on a busy host) could start 0.32 s
    after the last beat and the drive trip E25. The dead-man is fed before each such fit."""
    from servotool.tuning import identify
    from servotool.tuning.preflight import active_alarm

    sim, d, clock = set_up("dsx7e", load_ratio=4.0, seed=2)
    d.dead_man_waived = False
    made, silent = identify.trace_estimate, []

    def slow_estimate(*made_with):
        fit = made(*made_with)

        def slow_fit(trace, settings):
            silent.append(clock.now() - sim.firmware.last_host)
            clock.advance(0.3)
            return fit(trace, settings)

        return slow_fit

    monkeypatch.setattr(identify, "trace_estimate", slow_estimate)
    res = tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    assert res.ratio == pytest.approx(4.0, rel=0.1)
    assert silent and max(silent[:-1]) <= 0.2, silent  # the last fit comes after the motion
    assert active_alarm(d) is None


@pytest.mark.parametrize("seed", [1, 4])
def test_tune_inertia_returns_with_the_axis_at_rest_after_a_ringing_stop(sim_dir, seed):
    """DSX7E with a load of 6 on a speed loop set for far less (Pn101 25 Hz, Pn102 30 ms, ratio 2.5) swings
    through zero after each stop. One reading near zero was taken for rest: tune inertia returned (and a plan's
    next step read the speed) with the axis still turning at about 69 rpm (seeds 1, 4, 5, 6 of 1-6)."""
    sim, d, clock = set_up("dsx7e", 115200, load_ratio=6.0, seed=seed)
    for code, value in (("Pn101", 25.0), ("Pn102", 30.0)):
        entry = d.profile.entry(code)
        write_one(d, entry, eng_to_raw(entry, value))
    res = tune_inertia(d, TuneRequest(rigidity=12, gains=True), clock=clock)
    assert res.ratio == pytest.approx(6.0, rel=0.05)
    assert abs(sim.firmware.plant.true_speed_rpm) < 1.0


@pytest.mark.parametrize(("profile_id", "baud"), [("dsx7e", 115200), ("is620p", 57600)])
def test_a_heavy_gravity_axis_whose_loop_rings_after_the_stop_is_held_until_it_rests(sim_dir, profile_id, baud):
    """A load of 50 with 40 % gravity and 1 % noise (the bench's machines, seed 25): the loop rang after the
    identification's stop, the stop took a swing for a runaway and switched the servo off at 104 rpm, and the load
    fell (3.6 rev on DSX7E before its brake closed): COULD NOT CONFIRM THE MOTOR STOPPED. The servo now holds the
    axis until it rests. Judged on the simulated plant itself: servo off, at rest, not fallen."""
    from bench.inertia_accuracy import bench_travel

    sim, d, clock = set_up(
        profile_id, baud, load_ratio=50.0, friction=0.05, viscous=0.001, load_torque=-0.4, noise=0.01, seed=25, brake=1
    )
    try:
        tune_inertia(d, TuneRequest(dry_run=True, travel_rev=bench_travel(profile_id)), clock=clock)
    except IdentificationRefused:
        pass  # the fit may refuse; the stop must not fail
    plant = sim.firmware.plant
    assert not plant.servo_on and abs(plant.true_speed_rpm) < 1.0
    assert abs(plant.position_rev) < bench_travel(profile_id), plant.position_rev
