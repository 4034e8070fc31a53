"""Hold-to-run JOG and the soft travel limit, in-process on virtual time; the position across the counter's wrap;
the dead-man bound facts and the refusal of a link too slow for the beat."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.link.ports import LinkSettings
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings
from servotool.motion import deadman
from servotool.motion.hold import HoldToRun
from servotool.motion.jogger import Jogger
from servotool.motion.travel import AxisPosition, TravelLimit, TravelLimitHit
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup


def _virtual(profile_id: str = "dsx7e"):
    profile = load_profile(profile_id)
    clock = VirtualClock(10.0)
    sim = build_drive(profile, 1, clock, persist=False)
    return sim, Drive(VirtualLink([sim], clock), profile, 1), clock


def test_hold_to_run_keeps_moving_across_the_repeat_delay_and_stops_within_a_beat_of_the_last_repeat():
    clock = VirtualClock()
    hold = HoldToRun(clock, beat_s=0.1)
    assert hold.key(None) == 0  # nothing pressed: nothing moves
    assert hold.key(1) == 1  # pressed
    clock.advance(0.5)
    assert hold.key(None) == 1  # the keyboard's repeat delay
    clock.advance(0.1)
    assert hold.key(1) == 1  # repeating
    clock.advance(0.09)
    assert hold.key(None) == 1
    clock.advance(0.02)
    assert hold.key(None) == 0  # no repeat for more than a beat: let go
    assert hold.key(-1) == -1 and hold.key(0) == 0  # space stops at once
    clock.advance(1.0)
    assert hold.key(1) == 1
    clock.advance(0.71)
    assert hold.key(None) == 0  # a tap moves at most the first repeat delay


def test_a_held_key_jogs_and_letting_go_stops_within_a_beat(sim_dir):
    sim, d, clock = _virtual()
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(300, None)
    hold = HoldToRun(clock, jogger.keepalive_s)
    t0 = clock.now()
    stopped_at: list[float] = []
    polls = [0]

    def keys() -> int | None:
        t = clock.now() - t0
        polls[0] += 1
        if t > 3.0:
            return None  # quit
        pressed = 1 if polls[0] == 1 or 0.6 <= t < 1.5 else None  # press, repeat delay, repeats until 1.5 s
        direction = hold.key(pressed)
        if direction == 0 and not stopped_at and t > 0.1:
            stopped_at.append(t)
        return direction

    jogger.run(plan, command=keys)
    assert stopped_at and 1.5 < stopped_at[0] <= 1.5 + jogger.keepalive_s + 0.03
    assert abs(sim.firmware.plant.true_speed_rpm) < 3


def test_the_travel_limit_stops_an_interactive_jog_before_it_passes_the_limit(sim_dir):
    sim, d, clock = _virtual()
    jogger = Jogger(d, clock=clock)
    # 250 rpm: DSX7E's 500 ms watchdog lets a dead host's motor run on 2.1 rev, which the guard keeps ahead of it
    plan = jogger.plan(250, None, travel=TravelLimit(3.0, "--travel"))
    start = sim.firmware.plant.position_rev
    with pytest.raises(TravelLimitHit, match=r"travel limit ±3 rev \(--travel\) reached at \+\d\.\d\d rev"):
        jogger.run(plan, command=lambda: 1)  # a key that never lets go
    clock.advance(2.0)
    d.read_entries([d.profile.need_role("speed_feedback", "test")])
    assert abs(sim.firmware.plant.position_rev - start) <= 3.0
    assert abs(sim.firmware.plant.true_speed_rpm) < 3 and not sim.firmware.plant.servo_on


def test_a_timed_jog_over_the_travel_limit_is_refused_before_moving(sim_dir):
    sim, d, clock = _virtual()
    with pytest.raises(UsageError, match=r"travels about 10.00 rev, over the travel limit ±5 rev"):
        Jogger(d, clock=clock).plan(300, 2.0, travel=TravelLimit(5.0, "config file"))
    assert not sim.firmware.plant.servo_on


def test_the_axis_position_is_tracked_across_the_counter_wrap(sim_dir):
    _sim, d, _clock = _virtual()
    pos = AxisPosition(d)
    per_rev = d.profile.motor.counts_per_rev
    top = (1 << 31) - per_rev // 2  # half a turn below the s32 counter's top
    pos.update(top)
    assert pos.update(top + per_rev - (1 << 32)) == pytest.approx(1.0)  # wrapped to negative: +1 rev
    assert pos.update(top - (1 << 32) + 3 * per_rev) == pytest.approx(3.0)
    assert pos.update(top + per_rev // 2) == pytest.approx(-0.5 + 0.0, abs=1.0)  # and back across it
    assert pos.update(top) == pytest.approx(0.0)


def test_the_bound_is_facts_from_route_speed_beat_and_ramp(sim_dir):
    _sim, d, _clock = _virtual()
    # DSX7E: its watchdog Pn620 = 500 ms, then Pn513's 200 ms ramp read as time to the rated 3000 rpm: 0.04 s
    b = deadman.bound(d, 600, 0.1, 200.0)
    assert b.route == "drive_timeout" and b.stop_rev == pytest.approx(10 * (0.5 + 0.04 / 2))
    assert b.stop_s == pytest.approx(0.54) and deadman.sentence(b).endswith("within 5.20 rev (0.54 s)")
    _sim, d, _clock = _virtual("is620p")
    b = deadman.bound(d, 600, 0.1, 100.0)  # a segment: 3 beats at speed plus the stop (H11-15 per 1000 rpm)
    # ... and the braking of the segment before it, with the speed loop's lag (the stricter reading of the trigger)
    assert b.route == "segment" and b.stop_rev == pytest.approx(10 * 0.3 + 10 * 0.06 / 2 + 10 * 0.06 / 2 + 10 * 0.02)
    _sim, d, _clock = _virtual("sdc")
    b = deadman.bound(d, 600, 0.1, 100.0)
    assert b.route == "none" and b.stop_rev is None
    with pytest.raises(UsageError, match=r"no dead-man on this drive .* --no-dead-man"):
        deadman.check(b, waived=False)
    deadman.check(b, waived=True)


class _SlowLink(VirtualLink):
    settings = LinkSettings("COM1", LineSettings(baud=9600))


def test_a_link_too_slow_for_the_beat_is_refused_with_the_alternatives(sim_dir):
    profile = load_profile("is620p")
    clock = VirtualClock(10.0)
    sim = build_drive(profile, 1, clock, persist=False)
    d = Drive(_SlowLink([sim], clock), profile, 1)
    b = deadman.bound(d, 600, 0.1, 100.0)
    assert b.link_cycle_s > 0.05
    with pytest.raises(UsageError, match=r"cannot keep the dead-man beat.*faster baud rate.*slower speed"):
        deadman.check(b, waived=False)


def test_a_speed_route_on_a_real_port_reads_its_parameter_held_reference_once_and_puts_it_back(sim_dir):
    """SDC holds its speed reference in a parameter (PN22): read for the journal before the motion, that read is
    the one the enable zeroes and leave() puts back (a second read cost a request on a 9600 line)."""
    profile = load_profile("sdc")
    clock = VirtualClock(10.0)
    sim = build_drive(profile, 1, clock, persist=False)
    make_motion_setup(sim)
    d = Drive(VirtualLink([sim], clock), profile, 1, port="COM7")  # a real port: the journal is kept
    d.dead_man_waived = True
    before = sim.bank.effective_value("PN22")
    reads: list[str] = []
    read_entries = d.read_entries

    def counted(entries, *args, **kwargs):
        reads.extend(e.code for e in entries)
        return read_entries(entries, *args, **kwargs)

    d.read_entries = counted  # type: ignore[method-assign]
    jogger = Jogger(d, clock=clock)
    jogger.run(jogger.plan(200, 0.5))
    # For the journal; to see whether it needs putting back; the put-back's verifying read. Not again at enable.
    assert reads.count("PN22") == 3
    assert sim.bank.effective_value("PN22") == before
    assert abs(sim.firmware.plant.true_speed_rpm) < 3
