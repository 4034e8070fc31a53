"""The simulated drive's own protections and forced inputs, as the manuals document them, seen through its
registers on virtual time: SD25's forced DIs (So-57/So-58, section 7.10.9) and software overtravel fence (So-39,
AL-27), the locked-rotor trip, SDC's speed-saturation detection (PN79/PN120, AL-6) with the overload multiple as the
torque limit (PN65)."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.model.codec import parse_value
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.plant import DriveGains, Plant, PlantSettings, Protections
from servotool.sim.virtual import make_motion_setup

COUNTS = 131072


def sd25(regs, **settings):
    clock = VirtualClock(10.0)
    sim = build_drive(load_profile("sd25"), 1, clock, persist=False)
    make_motion_setup(sim)  # DI1 = JOGU, DI2 = JOGD, in effect after the power cycle
    sim.configure(noise=0.0, **settings)
    sim.firmware.reconfigure()
    return sim, regs(sim), clock


def run_for(r, clock: VirtualClock, seconds: float, every: float = 0.02) -> float:
    """Let time pass with the host reading the speed (rpm) now and then; the last speed read."""
    speed = r.drive.profile.role("speed_feedback")
    for _ in range(round(seconds / every)):
        clock.advance(every)
        rpm = r.read(speed.code) * speed.scale
    return rpm


def position_rev(r) -> float:
    return r.read("L938") + r.read("L936") / COUNTS


def test_forced_dis_take_their_levels_from_so57_alone_and_the_monitor_shows_the_forced_levels(sim_dir, regs):
    sim, r, clock = sd25(regs, inputs=0b100)  # DI3 wired closed
    assert r.read("L923") == 0b100  # forcing off: the terminals
    r.write("So-57", 0b001)  # JOGU in the forced value, forcing off: nothing moves
    assert abs(run_for(r, clock, 0.5)) < 1
    r.write("So-58", parse_value(sim.profile.entry("So-58"), "X=1", current=r.read("So-58")))
    assert run_for(r, clock, 0.8) == pytest.approx(100, abs=5)  # forced JOGU at So-13
    assert r.read("L923") == 0b001  # the forced levels, not the wired DI3
    sim.configure(inputs=0b000)  # a wired input opens: ignored while forced
    sim.firmware.reconfigure()
    assert r.read("L923") == 0b001 and run_for(r, clock, 0.3) == pytest.approx(100, abs=5)
    r.write("So-58", 0)  # released: the terminals again, JOGU low
    assert abs(run_for(r, clock, 1.0)) < 2 and r.read("L923") == 0


def test_the_other_reading_shows_the_terminals_while_forced(sim_dir, regs):
    sim, r, clock = sd25(regs, inputs=0b100, di_monitor=1)
    r.write("So-57", 0b101)
    r.write("So-58", 1)
    run_for(r, clock, 0.3)
    assert r.read("L923") == 0b100
    sim.configure(inputs=0)
    sim.firmware.reconfigure()
    assert r.read("L923") == 0


def test_a_wired_jogu_jogs_without_forcing_and_forcing_is_not_stored(sim_dir, regs):
    sim, r, clock = sd25(regs, inputs=0b001)
    assert run_for(r, clock, 0.8) == pytest.approx(100, abs=5)  # terminal JOG (L3384-3395)
    sim.configure(inputs=0)
    sim.firmware.reconfigure()
    assert abs(run_for(r, clock, 1.0)) < 2
    r.write("Po505", parse_value(sim.profile.entry("Po505"), "X=0", current=r.read("Po505")))  # writes to EEPROM
    r.write("So-58", 1)
    r.write("So-13", 250)
    sim.power_cycle()
    assert r.read("So-58") == 0 and r.read("So-13") == 250  # So-58 'not written to EEPROM' (L5260-5287)


def fence_here(r, turns: int, action: int) -> float:
    """A fence of `turns` either way around the axis (origin = the encoder's present position), So-39 = action."""
    start = position_rev(r)
    r.write("Po136", r.read("L936"))
    r.write("Po138", r.read("L938"))
    for code in ("Po142", "Po145"):
        r.write(code, turns)
    for code in ("Po140", "Po143"):
        r.write(code, 0)
    r.write("So-39", action)
    return start


def test_the_fence_that_stops_holds_the_axis_at_its_range_without_an_alarm(sim_dir, regs):
    _sim, r, clock = sd25(regs)
    r.write("So-13", 6000)  # 600 rpm
    start = fence_here(r, 2, 2)
    r.write("So-58", 1)
    r.write("So-57", 0b01)  # JOGU, then the host goes quiet
    run_for(r, clock, 2.0)
    assert position_rev(r) - start == pytest.approx(2.0, abs=0.1)  # stopped at the fence, not at infinity
    assert abs(run_for(r, clock, 0.5)) < 2 and r.read("L926") == 0
    r.write("So-57", 0b10)  # the reverse direction stays free
    run_for(r, clock, 0.5)
    assert position_rev(r) - start < 0.0


def test_the_fence_that_alarms_trips_al27(sim_dir, regs):
    _sim, r, clock = sd25(regs)
    r.write("So-13", 6000)  # 600 rpm
    start = fence_here(r, 1, 1)
    r.write("So-58", 1)
    r.write("So-57", 0b01)
    run_for(r, clock, 1.5)
    assert r.read("L926") == 27 and abs(run_for(r, clock, 0.5)) < 2
    assert position_rev(r) - start == pytest.approx(1.0, abs=0.2)


def test_the_factory_fence_leaves_the_axis_free_where_the_encoder_starts(sim_dir, regs):
    _sim, r, clock = sd25(regs)
    r.write("So-58", 1)
    r.write("So-57", 0b10)  # reverse: the encoder starts 100 turns clear of its wrap, inside +-1000 turns
    assert run_for(r, clock, 1.0) == pytest.approx(-100, abs=5)
    assert r.read("L926") == 0


def test_a_locked_rotor_trips_after_its_time():
    p = Plant(
        load_profile("sd25").motor,
        PlantSettings(coulomb_nm=1.27 * 1.5),  # a jam: more friction than the torque limit
        DriveGains(torque_limit_pct=100.0),
    )
    p.set_protections(Protections(locked_rotor_s=0.5))
    p.set_mode("speed")
    p.set_speed_command(300)
    p.advance_to(0.45)
    assert p.alarm is None
    p.advance_to(0.6)
    assert p.alarm == "locked_rotor"


def test_sdc_trips_al6_when_its_speed_regulator_stays_saturated(sim_dir, regs):
    clock = VirtualClock(10.0)
    sim = build_drive(load_profile("sdc"), 1, clock, persist=False)
    make_motion_setup(sim)
    sim.configure(noise=0.0, friction=1.0)
    sim.firmware.reconfigure()
    r = regs(sim)
    r.write("PN65", 50)  # the overload multiple as the torque limit: 50 % cannot break 100 % friction away
    r.write("PN79", 30)  # 0.3 s
    r.write("PN95", 1)  # servo on, then the speed reference (as the JOG route writes them)
    r.write("PN22", 300)
    run_for(r, clock, 0.25, every=0.05)
    assert r.read("UN-21") == 0
    run_for(r, clock, 0.2, every=0.05)
    assert r.read("UN-21") == 6  # AL-6, speed amplifier saturation
    r.write("PN95", 0)


def test_sdc_saturation_detection_off_does_not_trip(sim_dir, regs):
    clock = VirtualClock(10.0)
    sim = build_drive(load_profile("sdc"), 1, clock, persist=False)
    make_motion_setup(sim)
    sim.configure(noise=0.0, friction=1.0)
    sim.firmware.reconfigure()
    r = regs(sim)
    for code, raw in (("PN65", 50), ("PN79", 30), ("PN120", 1), ("PN95", 1), ("PN22", 300)):
        r.write(code, raw)
    run_for(r, clock, 1.0, every=0.05)
    assert r.read("UN-21") == 0
