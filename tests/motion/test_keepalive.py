"""The dead-man beat: its period follows the drive's watchdog, beats keep a motion running, silence stops it."""

from __future__ import annotations

import itertools
import threading
import time

import pytest

from servotool.clock import RealClock, VirtualClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.motion.jogger import Jogger
from servotool.motion.keepalive import KeepAlive, keepalive_interval_s
from servotool.ops import alarms
from servotool.ops.params import write_one
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink


def _virtual():
    profile = load_profile("dsx7e")
    clock = VirtualClock(100.0)
    sim_drive = build_drive(profile, 1, clock, persist=False)
    return sim_drive, Drive(VirtualLink([sim_drive], clock), profile, 1), clock


def test_the_beat_period_follows_the_drive_watchdog(sim_dir):
    _sim, d, clock = _virtual()
    timeout = d.profile.role("comm_timeout")
    write_one(d, timeout, 150)
    assert keepalive_interval_s(d) == pytest.approx(0.05)
    assert KeepAlive.for_drive(d, clock).interval_s == pytest.approx(0.05)
    write_one(d, timeout, 50)
    with pytest.raises(UsageError, match="too short"):
        keepalive_interval_s(d)


def test_a_beat_is_due_once_its_period_has_passed_since_the_last_write(sim_dir):
    _sim, d, clock = _virtual()
    beat = KeepAlive(d, 0.1, clock)
    assert not beat.due()
    clock.advance(0.101)
    assert beat.due()
    beat.beat()
    assert not beat.due()
    clock.advance(0.2)
    beat.sent()  # a motion command counts as a beat
    assert not beat.due()


def test_beats_keep_a_jog_running_and_silence_stops_it_with_the_comm_alarm(sim_dir):
    sim_drive, d, clock = _virtual()
    write_one(d, d.profile.role("comm_timeout"), 300)
    jogger = Jogger(d, keepalive_interval_s(d), clock=clock)
    jogger.set_speed(300)
    jogger.command(1)
    end = clock.now() + 2.0
    while clock.now() < end:  # reads advance the virtual clock by their wire time
        speed = jogger.speed()
        jogger.keepalive.beat_if_due()
    assert speed == pytest.approx(300, abs=30) and not alarms.current(d).active
    clock.advance(0.5)  # the host goes quiet for longer than the watchdog
    state = alarms.current(d)
    assert state.active and state.code == d.profile.alarm_of_kind("comm_timeout").code
    assert sim_drive.firmware.mode != "jog"


def test_a_computation_beside_a_motion_is_beaten_through_and_its_result_or_error_comes_back(sim_dir):
    """A fit between moves that takes longer than the watchdog (a busy host): beats go out all through it, from the
    motion's own thread (the computation touches no link), at the beat interval; on a virtual clock it runs inline."""
    _sim, d, _clock = _virtual()
    ka = KeepAlive(d, 0.02, RealClock())
    fed: list[tuple[float, str]] = []

    def feed(lead_s: float) -> None:
        fed.append((time.monotonic(), threading.current_thread().name))

    def work() -> str:
        time.sleep(0.3)
        return threading.current_thread().name

    start = time.monotonic()
    assert ka.while_computing(work, feed) == "servotool-compute"
    assert len(fed) >= 3 and {name for _t, name in fed} == {threading.current_thread().name}
    times = [start, *(t for t, _name in fed)]
    assert max(b - a for a, b in itertools.pairwise(times)) < 0.3  # never a whole computation apart

    def fails() -> None:
        raise ValueError("singular")

    with pytest.raises(ValueError, match="singular"):
        ka.while_computing(fails, feed)
    virtual = KeepAlive(d, 0.02, VirtualClock())
    assert virtual.while_computing(lambda: threading.current_thread().name, feed) == threading.current_thread().name


def test_a_computation_on_a_virtual_host_that_takes_time_is_fed_through_it(sim_dir):
    """VirtualClock(computing_s): the time a fit between moves takes on the host it stands for passes after the
    work, fed every half beat interval as a real host's is (a bench or test sees the pause the samples take)."""
    _sim, d, _clock = _virtual()
    clock = VirtualClock(10.0, computing_s=0.1)
    fed: list[float] = []
    assert KeepAlive(d, 0.02, clock).while_computing(lambda: "done", lambda _lead: fed.append(clock.now())) == "done"
    assert clock.now() == pytest.approx(10.1)
    assert fed[0] == 10.0 and max(b - a for a, b in itertools.pairwise(fed)) <= 0.01 + 1e-9 and fed[-1] >= 10.1 - 1e-9
