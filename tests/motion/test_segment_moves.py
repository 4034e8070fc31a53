"""A move from rest on the segment route (IS620P): its settings folded into one request, a segment of its own that
stops it (within the dead-man's bound, else the beat-sized segment), and a re-arm only when one is needed."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.codec import eng_to_raw
from servotool.model.loader import load_profile
from servotool.motion import deadman
from servotool.motion.moves import Mover
from servotool.motion.stop import stop_sequence
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup

BEAT_S = 0.1


def _jogger(sim_dir):
    profile = load_profile("is620p")
    clock = VirtualClock(100.0)
    sim = build_drive(profile, 1, clock, persist=False)
    make_motion_setup(sim)
    d = Drive(VirtualLink([sim], clock, 57600), profile, 1)
    jogger = Mover(d, BEAT_S, "test", clock)
    saved = jogger.snapshot(need_ramp=True)
    writes: list[tuple[int, list[int]]] = []
    write = d.link.write
    d.link.write = lambda unit, address, values, **kw: (
        writes.append((address, list(values))),
        write(unit, address, values, **kw),
    )[1]
    return sim, jogger, clock, writes, saved


def _ramp_raw(jogger: Mover, up_s: float, speed: float) -> int:
    """The ramp parameter (time to the profile's ramp reference speed) that reaches `speed` in up_s."""
    return eng_to_raw(jogger.profile.entry("H11-15"), up_s * 1000.0 * jogger.profile.ramp_rpm() / speed)


def test_a_move_that_stops_after_its_ramp_is_one_segment_and_needs_no_stop_write(sim_dir):
    sim, jogger, clock, writes, saved = _jogger(sim_dir)
    distance = jogger.profile.entry("H11-12")
    jogger.start(1, 600.0, _ramp_raw(jogger, 0.1, 600.0), stop_after_s=0.1)
    block = [v for a, v in writes if a == distance.address]
    assert len(block) == 1 and len(block[0]) == 4  # displacement, speed and ramp in one request
    # up 0.1 s, down as long (the ramp in whole ms per 1000 rpm: 167 ms, 0.2 % off)
    assert block[0][0] == pytest.approx(600.0 / 60.0 * 0.1 * 10000, rel=0.003)
    writes.clear()
    clock.advance(0.35)  # longer than two beats: never re-armed
    jogger.keep_alive()
    jogger.command(0)  # at the ramp's end: the segment brakes by itself
    assert writes == []
    clock.advance(0.5)
    assert abs(sim.firmware.plant.true_speed_rpm) < 5.0
    assert stop_sequence(jogger.drive, jogger, saved, wait_s=1.0, clock=clock).confirmed


def test_an_early_stop_brakes_and_a_long_move_keeps_the_beat_sized_segment(sim_dir):
    _sim, jogger, clock, writes, saved = _jogger(sim_dir)
    distance = jogger.profile.entry("H11-12")
    jogger.start(1, 600.0, _ramp_raw(jogger, 0.1, 600.0), stop_after_s=0.1)
    clock.advance(0.03)
    writes.clear()
    jogger.command(0)  # before its end: a braking segment now
    assert [a for a, _v in writes].count(distance.address) == 1
    clock.advance(0.5)
    # A move longer than the dead-man's segment is not one of its own: beat-sized, re-armed before it would end.
    ramp = _ramp_raw(jogger, 0.1, 600.0)
    jogger.start(-1, 600.0, ramp, stop_after_s=2.0)
    ref = jogger.profile.ramp_rpm()
    bound = deadman.segment_rev(600.0, BEAT_S, float(ramp), ref) * 10000
    assert abs(jogger.segments.written_distance()) == pytest.approx(bound, abs=2)
    writes.clear()
    clock.advance(1.5 * BEAT_S)
    jogger.keep_alive()
    assert writes == []  # one beat and a half: the segment still runs
    clock.advance(0.5 * BEAT_S)
    jogger.keep_alive()
    assert len(writes) == 2  # two beats: re-armed (the start edge)
    jogger.command(0)
    assert stop_sequence(jogger.drive, jogger, saved, wait_s=1.0, clock=clock).confirmed


def test_a_move_bounded_by_the_room_left_stops_there_by_itself_however_late_the_host_looks(sim_dir):
    """within_rev (the room a travel band leaves): the move's own segment no longer than that, and the drive stops the
    axis there with no write from the host, which here looks again only after 300 ms (a stalled host)."""
    _sim, jogger, clock, writes, saved = _jogger(sim_dir)
    start = _position_rev(jogger)
    jogger.start(1, 600.0, _ramp_raw(jogger, 0.1, 600.0), stop_after_s=0.1, within_rev=0.4)  # 1 rev unbounded
    assert jogger.own_segment_rev() == pytest.approx(0.4, abs=1e-4)
    writes.clear()
    clock.advance(0.3)
    jogger.keep_alive()
    jogger.command(0)
    assert writes == [] and jogger.ended_itself
    clock.advance(0.5)
    assert _position_rev(jogger) - start == pytest.approx(0.4, abs=0.02)
    assert stop_sequence(jogger.drive, jogger, saved, wait_s=1.0, clock=clock).confirmed
    # A move longer than the dead-man's segment, cut to the room left, is one of its own too; no room: one unit on.
    jogger.start(-1, 600.0, _ramp_raw(jogger, 0.1, 600.0), stop_after_s=2.0, within_rev=0.5)
    assert jogger.own_segment_rev() == pytest.approx(0.5, abs=1e-4) and jogger.segments.ends_itself
    clock.advance(2.5)
    jogger.command(0)
    jogger.start(1, 600.0, _ramp_raw(jogger, 0.1, 600.0), stop_after_s=0.1, within_rev=0.0)
    assert jogger.segments.written_distance() == 1
    clock.advance(0.5)
    jogger.command(0)
    assert stop_sequence(jogger.drive, jogger, saved, wait_s=1.0, clock=clock).confirmed


def _position_rev(jogger: Mover) -> float:
    """The motor's position (rev) as the drive reports it."""
    p = jogger.profile
    entry = p.need_role("position_feedback", "test")
    assert p.motor is not None
    return jogger.drive.read_entries([entry])[0].raw / p.motor.counts_per_rev
