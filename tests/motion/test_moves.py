"""Mover.keep_alive on a drive's own watchdog (DSX7E, Pn620 500 ms): the beat at two thirds of the timeout from a
caller on time, brought forward by the longest stall of a caller that overran the lead it gave, never more often
than the keep-alive interval; judged by when the beats reach the drive and whether its watchdog trips. Where the host
starved the watchdog, the words an alarm then gets (Mover.starved) name the stall."""

from __future__ import annotations

import itertools

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import DeviceError
from servotool.model.loader import load_profile
from servotool.motion import deadman
from servotool.motion.keepalive import keepalive_interval_s
from servotool.motion.moves import Mover
from servotool.ops import alarms
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup

# How often the caller looks when it is on time (an identification looks once a sample: 10 ms is a slow line's).
STEP_S = 0.01
# A beat's own write on the line, and the caller's look that finds it due: how late a beat may go out after the
# moment it became due.
SLACK_S = STEP_S + 0.005


class _Machine:
    """A DSX7E on virtual time with a move running, and the moments its keep-alive writes reached the drive."""

    def __init__(self, start: bool = True) -> None:
        profile = load_profile("dsx7e")
        self.clock = VirtualClock(100.0)
        self.sim = build_drive(profile, 1, self.clock, persist=False)
        make_motion_setup(self.sim)
        self.drive = Drive(VirtualLink([self.sim], self.clock, 115200), profile, 1)
        self.timeout_s = deadman.drive_timeout_s(self.drive)
        self.interval_s = keepalive_interval_s(self.drive)
        self.mover = Mover(self.drive, self.interval_s, clock=self.clock)
        self.beats: list[float] = []
        beat_entry = profile.entry("Fn032")  # the DSX7E's keep-alive (any write refreshes its watchdog)
        write = self.drive.link.write

        def seen_write(unit, address, values, **kw):
            if address == beat_entry.address:
                self.beats.append(self.clock.now())
            return write(unit, address, values, **kw)

        self.drive.link.write = seen_write
        if start:
            self.start()

    def start(self) -> None:
        self.mover.start(1, 300.0, 100)
        assert self.mover.dead_man is not None and self.mover.dead_man.route == "drive_timeout"

    def on_time(self, seconds: float, lead_s: float = 0.0) -> list[float]:
        """The caller looks every STEP_S for `seconds`, each time saying it looks again within lead_s; returns the
        gaps between the beats written meanwhile (the first from the beat before them, where there was one)."""
        first = len(self.beats)
        end = self.clock.now() + seconds
        while self.clock.now() < end:
            self.clock.advance(STEP_S)
            self.mover.keep_alive(lead_s)
        beats = self.beats[max(first - 1, 0) :]
        return [b - a for a, b in itertools.pairwise(beats)]

    def stall(self, seconds: float, said_s: float = 0.0) -> None:
        """The caller looks, saying it looks again within said_s, and looks again only `seconds` later."""
        self.mover.keep_alive(said_s)
        self.clock.advance(seconds)
        self.mover.keep_alive()

    def tripped(self) -> bool:
        return alarms.current(self.drive).active


@pytest.fixture
def machine(sim_dir) -> _Machine:
    return _Machine()


def test_a_caller_on_time_gets_its_beat_when_two_thirds_of_the_timeout_have_passed(machine):
    assert machine.timeout_s == pytest.approx(0.5) and machine.interval_s == pytest.approx(0.5 / 3)
    gaps = machine.on_time(3.0)
    assert len(gaps) >= 6
    assert all(2 / 3 * machine.timeout_s <= g <= 2 / 3 * machine.timeout_s + SLACK_S for g in gaps), gaps
    assert not machine.tripped()


def test_a_stall_brings_every_later_beat_forward_by_the_longest_stall_seen(machine):
    machine.on_time(0.5)
    machine.stall(0.12)  # more than half the spare third (83 ms) late: the host stalled
    due = 2 / 3 * machine.timeout_s - 0.12
    gaps = machine.on_time(2.0)[1:]  # (the first gap holds the stall)
    assert gaps and all(due <= g <= due + SLACK_S for g in gaps), gaps
    machine.stall(0.09)  # a shorter stall later: the longest is kept
    gaps = machine.on_time(2.0)[1:]
    assert gaps and all(due <= g <= due + SLACK_S for g in gaps), gaps
    assert not machine.tripped()


def test_a_caller_late_by_less_than_half_the_spare_third_is_not_taken_for_a_stalled_host(machine):
    machine.on_time(0.5)
    machine.stall(0.07)  # 70 ms between looks, said 0: late by less than 83 ms
    machine.stall(0.2, said_s=0.15)  # it said 150 ms and took 200: late by 50 ms
    gaps = machine.on_time(2.0)[1:]
    assert gaps and all(2 / 3 * machine.timeout_s <= g <= 2 / 3 * machine.timeout_s + SLACK_S for g in gaps), gaps
    machine.stall(0.12, said_s=0.02)  # it said 20 ms and took 120: late by 100 ms, a stall
    due = 2 / 3 * machine.timeout_s - 0.12
    gaps = machine.on_time(2.0)[1:]
    assert gaps and all(due <= g <= due + SLACK_S for g in gaps), gaps


def test_however_long_the_stall_the_beats_come_no_more_often_than_the_keepalive_interval(machine):
    """A stall longer than the timeout (the watchdog has tripped, or the gap came before the motion) is a lead of at
    most the timeout: the beat then goes out every interval (a third of the timeout), never at every look."""
    machine.on_time(0.5)
    machine.stall(5.0)
    gaps = machine.on_time(2.0)[1:]
    assert len(gaps) >= 10
    assert all(machine.interval_s <= g <= machine.interval_s + SLACK_S for g in gaps), gaps


def test_a_host_that_stalled_once_keeps_the_watchdog_fed_through_its_next_stalls(machine):
    """The host stalls 200 ms right after the move starts (harmless: the start was a beat), then 200 ms after each
    320 ms of looks. A beat left to two thirds of 500 ms would go out after a look at 320 ms only at 333 ms: the
    stall then ends 520 ms after the last beat and the watchdog trips (E25). Learnt from the first stall, the beat
    goes out early enough."""
    machine.stall(0.2)
    for _cycle in range(8):
        machine.on_time(0.32)
        machine.stall(0.2)
    assert not machine.tripped(), alarms.current(machine.drive)
    assert machine.sim.firmware.mode == "jog"


def test_a_watchdog_the_host_starved_is_named_as_the_host_stalling(machine):
    """A 400 ms stall when the beat was left to 333 ms: the drive's 500 ms watchdog trips (E25), and the words a
    procedure adds to that alarm (Mover.starved: identification, step check) name the stall and its length."""
    machine.on_time(0.32)
    assert machine.mover.starved() == ""  # on time: nothing to say
    machine.stall(0.4)
    assert machine.tripped()
    said = machine.mover.starved()
    assert "the host stalled" in said and "no request for 400 ms against its 500 ms timeout" in said, said
    machine.stall(0.7)  # longer than the timeout: as long as the timeout at least
    assert "no request for 500 ms or more against its 500 ms timeout" in machine.mover.starved()


def test_a_stall_inside_the_spare_third_is_not_named_for_an_alarm(machine):
    """A 120 ms stall, and a 150 ms gap between a caller's own samples, fit in the third of the timeout a beat
    leaves spare: no alarm it comes with is put on the host (a 200 ms gap is)."""
    machine.on_time(0.5)
    machine.stall(0.12)
    assert machine.mover.starved() == "" and machine.mover.starved(0.15) == ""
    assert "no request for 200 ms" in machine.mover.starved(0.2)


def test_a_motion_whose_watchdog_the_host_starved_ends_naming_the_stall(sim_dir):
    """The same stall inside a motion's stop scope: the stop finds E25 latched, and the failure says the host stalled
    (where no procedure looked for the alarm itself: a tune ended "the drive latched alarm E25 ... during the
    motion" on a loaded host)."""
    machine = _Machine(start=False)
    with pytest.raises(DeviceError, match=r"E25 .* \(its host watchdog: no request for 400 ms .* the host stalled"):
        with machine.mover.stopping():
            machine.start()
            machine.on_time(0.32)
            machine.stall(0.4)
