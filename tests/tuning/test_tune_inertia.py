"""tune inertia in-process on virtual time: the use case (tune_inertia) and the identification under it; fast,
and a test can act on the machine mid-motion."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink
from servotool.tuning import identify, planning
from servotool.tuning.errors import IdentificationFailed, TravelExceeded, TuneDeclined
from servotool.tuning.tune import TuneRequest, tune_inertia


def _virtual(ratio: float = 3.0, profile_id: str = "dsx7e"):
    """(simulated drive, host Drive, clock) of a drive with the given load, on virtual time."""
    profile = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim_drive = build_drive(profile, 1, clock, persist=False)
    sim_drive.settings.update(load_ratio=ratio, friction=0.05)
    sim_drive.firmware.reconfigure()
    return sim_drive, Drive(VirtualLink([sim_drive], clock), profile, 1), clock


def _after_motion_reads(sim_drive, reads: int, action) -> dict[str, float]:
    """Run action(plant) once, on the first read after `reads` reads with the motor turning; returns the moment."""
    plant, seen, when = sim_drive.firmware.plant, [0], {}

    def hook(_drive) -> None:
        if "t" not in when and abs(plant.true_speed_rpm) > 50:
            seen[0] += 1
            if seen[0] >= reads:
                when["t"] = plant.time
                action(plant)

    sim_drive.on_read.append(hook)
    return when


def _run_host(ident: identify.Identifier, timing) -> identify.Result:
    """What `tune inertia` does with the default options: rest check, automatic plan, host identification."""
    plan, rest = planning.plan_host_motion(ident.drive, timing)
    return ident.run_host(plan, rest=rest)


def test_alarm_in_the_middle_of_the_motion_stops_it_and_refuses(sim_dir):
    sim_drive, d, timing = _virtual()
    p = d.profile
    jog_params = d.read_entries([p.role("jog_speed"), p.role("jog_accel")])
    tripped = _after_motion_reads(sim_drive, 150, lambda plant: plant.raise_alarm("overload"))
    plant, late = sim_drive.firmware.plant, []
    # the plant's own speed, not the drive's readings (which jitter by a few rpm at rest)
    sim_drive.on_read.append(
        lambda _d: late.append(abs(plant.true_speed_rpm)) if plant.time > tripped.get("t", math.inf) + 0.2 else None
    )
    ident = identify.Identifier(d, timing)
    with pytest.raises(IdentificationFailed, match="alarm E09"):
        _run_host(ident, timing)
    assert "t" in tripped  # the alarm came during the motion
    trace_t0 = timing.now() - ident.trace.t[-1]
    # the identification gave up within the move the alarm ended (no further moves were started) ...
    assert ident.trace.t[-1] + trace_t0 - tripped["t"] < 1.0
    assert max(late, default=0.0) < 1.0  # ... and nothing moved once the drive had stopped
    # the servo is off and the JOG parameters are back as they were
    assert sim_drive.firmware.mode == "off" and not sim_drive.firmware.plant.servo_on
    assert [r.raw for r in d.read_entries([p.role("jog_speed"), p.role("jog_accel")])] == [r.raw for r in jog_params]


def test_travel_check_stops_an_axis_that_runs_away(sim_dir):
    # After the pilot a load torque beyond the torque limit takes over (a slipping coupling on a hoist, say): no
    # stopping distance the guard plans for helps, only the travel check in the sampling loop stops the motion.
    sim_drive, d, timing = _virtual()
    rated = d.profile.motor.rated_torque_nm

    def overload(plant) -> None:
        plant.set_settings(replace(plant.settings, load_torque_nm=3.5 * rated))

    _after_motion_reads(sim_drive, 150, overload)
    with pytest.raises(TravelExceeded, match="travel limit 2 rev") as raised:
        _run_host(identify.Identifier(d, timing), timing)
    plant = sim_drive.firmware.plant
    assert sim_drive.firmware.mode == "off" and not plant.servo_on
    # The stop saw the motor speed up instead of slowing and switched the servo off at once; the load keeps
    # driving it (no brake), which the stop reads back and says instead of "stopped".
    report = raised.value.stop_report
    assert report.servo_on is False and not report.confirmed
    assert "speed reads" in report.describe() and report.describe().startswith("COULD NOT CONFIRM THE MOTOR STOPPED")


def test_an_active_alarm_refuses_before_any_motion(sim_dir):
    sim_drive, d, _clock = _virtual()
    sim_drive.firmware.plant.raise_alarm("overload")
    with pytest.raises(UsageError, match="alarm E09"):
        tune_inertia(d, TuneRequest())
    assert sim_drive.firmware.mode == "off"


def _raw(d: Drive, code: str) -> int:
    return d.read_entries([d.profile.entry(code)])[0].raw


def test_a_dry_run_identifies_and_writes_nothing(sim_dir):
    _sim, d, clock = _virtual(ratio=4.0)
    before = {c: _raw(d, c) for c in ("Pn004", "Pn101", "Pn102")}
    res = tune_inertia(d, TuneRequest(gains=True, rigidity=14, dry_run=True), clock=clock)
    assert res.ratio == pytest.approx(4.0, rel=0.05) and res.proposal.parameter.code == "Pn004"
    assert res.written == [] and res.persisted is None and not res.ratio_stored and not res.gains_written
    assert {c.role for c in res.proposal.gain_changes} >= {"speed_loop_gain", "speed_loop_integral"}
    assert {c: _raw(d, c) for c in ("Pn004", "Pn101", "Pn102")} == before


def test_the_ratio_and_gains_are_written_once_approved_and_not_when_declined(sim_dir):
    _sim, d, clock = _virtual(ratio=4.0)
    seen = []
    res = tune_inertia(
        d, TuneRequest(gains=True, rigidity=14), clock=clock, on_proposal=seen.append, approve_write=lambda _p: False
    )
    assert len(seen) == 1 and res.written == [] and _raw(d, "Pn004") == 250  # the factory 1.5
    res = tune_inertia(d, TuneRequest(gains=True, rigidity=14), clock=clock)
    assert res.ratio_stored and res.gains_written
    assert res.written[0][0].code == "Pn004" and _raw(d, "Pn004") == res.proposal.parameter_raw
    speed_gain = next(c for c in res.proposal.gain_changes if c.role == "speed_loop_gain")
    assert _raw(d, speed_gain.entry.code) == speed_gain.raw


def test_declining_the_motion_moves_nothing(sim_dir):
    sim_drive, d, clock = _virtual()
    with pytest.raises(TuneDeclined):
        tune_inertia(d, TuneRequest(), clock=clock, approve_motion=lambda _m: False)
    assert sim_drive.firmware.plant.true_speed_rpm == 0.0


def test_the_writes_follow_the_drives_eeprom_rule(sim_dir):
    """IS620P stores every write while H0C-13 = 1: save=False keeps the result out of EEPROM (a power cycle loses
    it) and puts the switch back."""
    sim_drive, d, clock = _virtual(ratio=4.0, profile_id="is620p")
    for code, raw in (
        ("H02-00", 1),
        ("H05-00", 2),
        ("H05-02", 10000),
        ("H11-00", 0),
        ("H0C-09", 1),
        ("H17-00", 1),
        ("H17-02", 28),
    ):  # the segment route's setup
        d.write_verified(d.profile.entry(code), raw)
    old = _raw(d, "H08-15")
    res = tune_inertia(d, TuneRequest(save=False), clock=clock)
    assert res.persisted is False and _raw(d, "H08-15") == res.proposal.parameter_raw != old
    assert _raw(d, "H0C-13") == 1
    sim_drive.power_cycle()
    assert _raw(d, "H08-15") == old
    res = tune_inertia(d, TuneRequest(), clock=clock)  # as the drive is set: stored
    assert res.persisted is True
    sim_drive.power_cycle()
    assert _raw(d, "H08-15") == res.proposal.parameter_raw


def test_a_profile_without_an_inertia_ratio_parameter_is_measured_and_nothing_written(sim_dir):
    _sim, d, clock = _virtual(ratio=5.0, profile_id="sdc")
    d.write_verified(d.profile.entry("PN4"), 3)  # the JOG route's setup
    d.dead_man_waived = True  # SDC has no dead-man route
    res = tune_inertia(d, TuneRequest(), clock=clock)
    assert res.ratio == pytest.approx(5.0, rel=0.05) and res.identified.old_ratio is None
    assert res.proposal.parameter is None and res.written == [] and res.persisted is None


def test_the_drive_method_keeps_the_dead_man_rule_of_the_host_method(sim_dir):
    """The drive's own identification moves the axis too: on a drive whose dead-man route stops nothing it needs the
    same acknowledgement (--no-dead-man) as the host method, and nothing moves without it."""
    from servotool.model.profile import DeadManRoute

    sim_drive, d, clock = _virtual(ratio=3.0)
    d.profile = replace(d.profile, dead_man=DeadManRoute(route="none", reason="no watchdog here", source="test"))
    with pytest.raises(UsageError, match="no dead-man on this drive"):
        tune_inertia(d, TuneRequest(method="drive", dry_run=True), clock=clock)
    assert sim_drive.firmware.plant.position_rev == 0.0 and sim_drive.firmware.ident is None  # nothing moved
    d.dead_man_waived = True
    res = tune_inertia(d, TuneRequest(method="drive", dry_run=True), clock=clock)
    assert res.ratio == pytest.approx(3.0, rel=0.1)
