"""Drive firmware behaviour of the simulator on virtual time: watchdog, alarm history, holding, status words and
the motion setup, seen through the drive's registers."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from servotool.clock import VirtualClock
from servotool.model.codec import parse_value
from servotool.model.loader import load_profile
from servotool.motion import deadman
from servotool.ops.alarms import describe
from servotool.sim.firmware import build_drive


def run_for(r, clock: VirtualClock, seconds: float, every: float = 0.05) -> None:
    for _ in range(round(seconds / every)):
        clock.advance(every)
        r.read("Un000")


def holding_drive(regs, load_torque: float, *, brake: bool = True, torque_limit: float = 300.0, without_kind: str = ""):
    """A DSX7E with a gravity load whose Un014 stands in for a following-error monitor (DSX7E has none)."""
    profile = load_profile("dsx7e")
    profile = replace(
        profile,
        roles={**profile.roles, "following_error": "Un014"},
        alarms=[a for a in profile.alarms if a.kind != without_kind],
    )
    clock = VirtualClock(50.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.configure(load_torque=load_torque, brake=int(brake), noise=0.0)
    sim.firmware.reconfigure()
    r = regs(sim)
    for code in ("Pn025", "Pn026"):
        r.write(code, round(torque_limit / profile.entry(code).scale))
    return r, clock


def test_a_latched_alarm_enters_the_history_once_and_again_after_a_reset(sim_dir, regs):
    clock = VirtualClock(100.0)
    r = regs(build_drive(load_profile("dsx7e"), 1, clock, persist=False))
    r.write("Fn001", 1)  # JOG forward, then the host goes quiet
    clock.advance(2.0)
    for _ in range(5):  # the latched alarm is seen on every read, recorded once
        r.read("Un100")
        clock.advance(0.1)
    assert r.read("Un100") == 0x25  # the current fault (本次); the log's Un106.. keep the faults before it (前1次..)
    assert r.history() == [0, 0, 0]
    r.write("Fn030", 1)  # alarm reset
    assert r.read("Un100") == 0 and r.history() == [0x25, 0, 0]
    r.write("Fn001", -1)
    clock.advance(2.0)
    assert r.read("Un100") == 0x25 and r.history() == [0x25, 0, 0]
    r.write("Fn030", 1)
    assert r.read("Un100") == 0 and r.history() == [0x25, 0x25, 0]


def test_a_reset_while_the_cause_remains_keeps_the_alarm_latched_without_a_second_entry(sim_dir, regs):
    r, clock = holding_drive(regs, 2.0, brake=False)  # falls to overspeed and keeps falling
    run_for(r, clock, 1.0)
    code = r.drive.profile.alarm_of_kind("overspeed").code
    r.write("Fn030", 1)
    run_for(r, clock, 0.2)
    assert r.read("Un100") == code and r.history() == [0, 0, 0]  # still the current fault, entered once
    assert [rec["code"] for rec in r.drive.firmware.alarms.records()] == [code]


def test_servo_on_holds_position_against_gravity_through_the_position_loop(sim_dir, regs):
    r, clock = holding_drive(regs, 0.5)
    r.write("Pn620", 60000)  # a 60 s watchdog: nobody sends keep-alives here
    r.write("Fn033", 1)  # servo on, standing still
    run_for(r, clock, 0.02, every=0.002)
    sag = abs(r.read("Un014"))
    assert r.drive.firmware.plant.mode == "position" and r.read("Un100") == 0
    run_for(r, clock, 1.0)
    counts_per_rev = r.drive.profile.motor.counts_per_rev
    assert abs(r.read("Un012")) < 0.002 * counts_per_rev  # the position loop pulled the sag back
    assert abs(r.read("Un014")) < 0.002 * counts_per_rev
    assert sag != 0  # the following error was published while the load sagged


def test_gravity_beyond_the_torque_limit_while_holding_ends_in_the_following_error_alarm(sim_dir, regs):
    r, clock = holding_drive(regs, 1.5, torque_limit=100)  # a load the motor cannot hold at 100 %
    r.write("Pn620", 60000)
    r.write("Fn033", 1)
    run_for(r, clock, 0.02, every=0.01)
    assert r.read("Un100") == 0
    worst = 0
    for _ in range(100):
        clock.advance(0.005)
        worst = max(worst, abs(r.read("Un014")))
        if r.read("Un100"):
            break
    code = r.drive.profile.alarm_of_kind("following_error").code
    assert r.read("Un100") == code and r.drive.firmware.alarms.records()[0]["code"] == code
    assert worst > 2.5 * r.drive.profile.motor.counts_per_rev  # the error grew to the 3 rev default limit
    run_for(r, clock, 1.0)  # alarm stop, servo off, the brake closes and holds
    at_rest = r.read("Un012")
    run_for(r, clock, 1.0)
    assert r.read("Un012") == at_rest and not r.drive.firmware.plant.servo_on


def test_the_brake_holds_a_gravity_load_with_servo_off_and_without_it_the_axis_falls(sim_dir, regs):
    r, clock = holding_drive(regs, 0.5, brake=True)
    run_for(r, clock, 1.0)
    assert r.read("Un012") == 0
    r, clock = holding_drive(regs, 0.5, brake=False)
    run_for(r, clock, 0.2)
    assert r.read("Un012") < -r.drive.profile.motor.counts_per_rev  # falling, only friction against it
    assert r.read("Un100") == 0


def test_an_alarm_raised_with_the_servo_off_enters_the_history(sim_dir, regs):
    r, clock = holding_drive(regs, 2.0, brake=False)  # no brake: the load falls until it is over speed
    run_for(r, clock, 1.0)
    code = r.drive.profile.alarm_of_kind("overspeed").code
    assert not r.drive.firmware.plant.servo_on
    assert r.read("Un100") == code and r.drive.firmware.alarms.records()[0]["code"] == code


def test_a_trip_the_profile_lists_no_alarm_for_shows_as_unknown_not_as_another_alarm(sim_dir, regs):
    r, clock = holding_drive(regs, 2.0, brake=False, without_kind="overspeed")
    run_for(r, clock, 1.0)
    code = r.read("Un100")
    assert code and not describe(r.drive.profile, code).known
    assert code not in {a.code for a in r.drive.profile.alarms}


def test_the_position_counter_wraps_like_a_multi_turn_counter(sim_dir, regs):
    r, _clock = holding_drive(regs, 0.0)
    counts = r.drive.profile.motor.counts_per_rev
    r.drive.firmware.plant.theta = 2 * math.pi * (2**31 + counts // 2) / counts  # half a turn past the top
    assert r.read("Un012") == -(2**31) + counts // 2


def test_the_following_error_limit_comes_from_the_drive_parameter_where_it_has_one(sim_dir, regs):
    profile = load_profile("is620p")
    sim = build_drive(profile, 1, VirtualClock(), persist=False)
    assert sim.firmware.plant.gains.following_limit_rev == 3.0  # H0A-10's default: 3 rev of a 20-bit encoder
    regs(sim).write("H0A-10", 8 << 16)  # 2^19 counts
    assert sim.firmware.plant.gains.following_limit_rev == 0.5


def test_a_drive_without_a_documented_timeout_keeps_running_when_the_host_goes_quiet(sim_dir, regs):
    """SDC documents no comm timeout: like the real drive, the strict simulator keeps running after the host is
    gone; only the labelled fake watchdog (off by default) stops host-commanded motion, without an alarm."""
    profile = load_profile("sdc")
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    r = regs(sim)
    r.write("PN4", 3)  # the JOG mode (the route's setup)
    r.write("PN95", 1)  # servo on
    r.write("PN22", 300)  # commanded motion ...
    for _ in range(50):  # ... and then 5 s of silence
        clock.advance(0.1)
        r.read("UN-1")
    assert r.read("UN-1") > 250 and r.read("UN-21") == 0 and sim.firmware.plant.servo_on
    sim.configure(fake_watchdog=1)  # NOT REAL: sim config --fake-watchdog on
    r.write("PN22", 300)
    for _ in range(20):
        clock.advance(0.1)
        r.read("UN-1")
    assert abs(r.read("UN-1")) < 10 and r.read("UN-21") == 0 and not sim.firmware.plant.servo_on


def test_sd25_reports_servo_on_and_motion_in_its_do_function_state_word(sim_dir, regs):
    """SD25 has no status word: its DO-function state (944: SON-O, TGON, ALM) serves as one, by bit name."""
    profile = load_profile("sd25")
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    r = regs(sim)
    status = profile.role("servo_status")
    assert r.read(status.code) == 0
    sim.firmware.plant.set_mode("speed")  # servo on (as JOG does), turning
    sim.firmware.plant.set_speed_command(300)
    for _ in range(5):
        clock.advance(0.05)
        r.read("L904")
    word = r.read(status.code)
    assert word & 0b110 == 0b110 and not word & (1 << 6)  # SON-O and TGON set, ALM clear


def jog_forward(r, clock: VirtualClock) -> float:
    """Command forward host motion by the profile's route (JOG trigger, or servo-on + speed reference); speed after."""
    p = r.drive.profile
    if p.role("jog") is not None:
        r.write(p.roles["jog"], 1)
    elif p.role("segment_start") is not None:  # a 5 rev move at 300 rpm, started by an edge
        r.write(p.roles["segment_speed"], 300)
        r.write(p.roles["segment_distance"], 50000)
        r.write(p.roles["servo_on"], 1)
        r.write(p.roles["segment_start"], 1 | p.dead_man.start_value)
    else:
        r.write(p.roles["servo_on"], 1)
        r.write(p.roles["speed_reference"], 300)
    for _ in range(10):  # the keep-alive a host would send
        clock.advance(0.05)
        r.write(
            p.roles.get("jog") or p.roles["servo_on"], 1 | (p.dead_man.start_value if p.role("segment_start") else 0)
        )
    return r.read(p.roles["speed_feedback"]) * p.role("speed_feedback").scale


def test_host_motion_writes_move_nothing_until_the_drive_is_set_up(sim_dir, regs):
    """A third-party master writing the motion registers of a drive not set up sees it stand still, as a real
    drive would; after the setup (and, for SD25, the power cycle) the same writes move it."""
    setups = {
        "is620p": {"H02-00": 1, "H05-00": 2, "H05-02": 10000, "H11-00": 0, "H0C-09": 1, "H17-00": 1, "H17-02": 28},
        "sdc": {"PN4": 3},
        "sd25": {"Po407": 26, "Po408": 27, "So-58": 1},
    }
    for pid, setup in setups.items():
        clock = VirtualClock(10.0)
        sim = build_drive(load_profile(pid), 1, clock, persist=False)
        sim.configure(noise=0.0)
        sim.firmware.reconfigure()
        r = regs(sim)
        assert abs(jog_forward(r, clock)) < 1 and sim.firmware.mode == "off", pid
        if pid == "sd25":  # writes stored in EEPROM, as `param set --save` arranges
            switch = sim.profile.entry("Po505")
            r.write("Po505", parse_value(switch, "X=0", current=r.read("Po505")))
        for code, raw in setup.items():
            r.write(code, raw)
        if pid == "sd25":
            assert abs(jog_forward(r, clock)) < 1, "Po407/Po408 act only after a power cycle"
            sim.power_cycle()
            r.write("So-58", 1)  # the real drive clears So-58 at power-up: set it again
        assert jog_forward(r, clock) > 90, pid  # it moves


def _segment_drive(regs, restart: bool):
    """A simulated IS620P set up for its segment route (3 rev at 600 rpm, 100 ms ramp), its trigger semantics
    chosen; (sim, registers, clock)."""
    profile = load_profile("is620p")
    clock = VirtualClock(5.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings["segment_restart"] = int(restart)
    r = regs(sim)
    for code, value in {
        "H02-00": 1,
        "H05-00": 2,
        "H05-02": 10000,
        "H11-00": 0,
        "H0C-09": 1,
        "H17-00": 1,
        "H17-02": 28,
        "H11-14": 600,
        "H11-12": 30000,
        "H11-15": 100,
    }.items():
        r.write(code, value)
    return sim, r, clock


@pytest.mark.parametrize("restart", [False, True])
def test_a_segment_move_ends_and_stops_by_itself_at_its_end(sim_dir, regs, restart):
    """IS620P's route: one start edge runs segment 1 (relative, at H11-14 rpm) to its end and holds there, with no
    host traffic at all, under either reading of the trigger."""
    sim, r, clock = _segment_drive(regs, restart)
    start = sim.firmware.plant.position_rev
    r.write("H31-00", 1)  # servo on
    r.write("H31-00", 3)  # start edge: 3 rev at 600 rpm
    clock.advance(0.2)
    assert r.read("H0B-00") > 500  # running
    clock.advance(5.0)  # the host is gone
    r.read("H0B-00")
    moved = sim.firmware.plant.position_rev - start
    assert 2.8 < moved <= 3.0 and abs(r.read("H0B-00")) < 5 and sim.firmware.plant.servo_on


def test_the_older_reading_restarts_a_running_segment_from_where_the_axis_is(sim_dir, regs):
    """sim config --segment-restart on: a new edge during a move starts a fresh segment from the present
    position (the reading the simulator had before issue 29)."""
    sim, r, clock = _segment_drive(regs, restart=True)
    start = sim.firmware.plant.position_rev
    r.write("H31-00", 1)
    r.write("H31-00", 3)
    clock.advance(0.1)
    r.write("H31-00", 1)
    r.write("H31-00", 3)  # re-armed during the move: 3 rev from this point
    here = sim.firmware.plant.position_rev
    clock.advance(5.0)
    r.read("H0B-00")
    assert sim.firmware.plant.position_rev - here <= 3.0 + 0.01  # the loop lags the braking ramp by a few mrev
    assert 3.3 < sim.firmware.plant.position_rev - start <= 4.0


def test_the_strict_reading_brakes_on_a_falling_edge_and_queues_a_rising_one(sim_dir, regs):
    """By default (unverified: a third-party account of Inovance firmware, issue 29): a falling edge brakes the
    running segment; a rising edge during it waits until it has ended and settled, then runs segment 1 afresh;
    the whole run-on is one braking and one segment, as the bound (motion/deadman.py) allows for."""
    sim, r, clock = _segment_drive(regs, restart=False)
    r.write("H31-00", 1)
    r.write("H31-00", 3)
    clock.advance(0.1)
    r.read("H0B-00")
    here = sim.firmware.plant.position_rev
    r.write("H31-00", 1)  # falling edge: brakes
    r.write("H31-00", 3)  # rising edge during the braking: queued
    clock.advance(0.02)
    braking_at = abs(r.read("H0B-00"))
    clock.advance(0.02)
    assert abs(r.read("H0B-00")) < braking_at < 590  # braking, not restarted
    clock.advance(5.0)
    r.read("H0B-00")
    braking = 10.0 * 0.06 / 2 + 10.0 * deadman.SEGMENT_BRAKE_LAG_S  # 600 rpm, 100 ms per 1000 rpm, the loop's lag
    assert 3.0 < sim.firmware.plant.position_rev - here <= 3.0 + braking + 0.02
    assert abs(r.read("H0B-00")) < 5 and sim.firmware.plant.servo_on
    # A falling edge alone brakes, and nothing follows.
    r.write("H31-00", 1)
    r.write("H31-00", 3)
    clock.advance(0.1)
    r.read("H0B-00")
    here = sim.firmware.plant.position_rev
    r.write("H31-00", 1)
    clock.advance(2.0)
    r.read("H0B-00")
    assert sim.firmware.plant.position_rev - here <= braking + 0.02
