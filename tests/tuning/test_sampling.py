"""The identification's trace (tuning.sampling): the speed brought onto the torque's times, the sampling rate."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from servotool.sim.virtual import TURNAROUND_S, HostStalls, wire_time
from servotool.tuning.fit.signals import anchored
from servotool.tuning.sampling import LATE_S, LATE_SHARE, Sampler, Trace
from tests.tuning.test_tune_robustness import set_up


def test_speed_read_a_request_before_the_torque_is_brought_onto_the_torques_times():
    """SD25 cannot read speed and torque in one request: the speed is older than the torque by one request."""
    trace = Trace(
        t=[0.1, 0.2, 0.3],
        speed=[0.0, 100.0, 200.0],
        torque=[1.0, 1.0, 1.0],
        position=[None] * 3,
        speed_t=[0.05, 0.15, 0.25],
    )
    assert trace.aligned_speed() == pytest.approx([50.0, 150.0, 200.0])  # the last one is held, not guessed
    assert Trace(t=[0.1, 0.2], speed=[1.0, 2.0]).aligned_speed() == [1.0, 2.0]  # read together: unchanged


def test_a_curving_speed_is_brought_onto_the_torques_times_by_a_cubic_not_a_line():
    """A sluggish loop rings through its ramps: between two speed reads a straight line misplaces the speed at the
    torque's time."""
    ts = np.arange(0.0, 1.0, 0.035)  # SD25 at 19200: a speed read every 35 ms
    t = ts + 0.0175  # the torque a request later
    speed = 1000.0 * np.sin(2 * np.pi * 1.5 * ts)
    trace = Trace(t=list(t), speed=list(speed), torque=[0.0] * ts.size, position=[None] * ts.size, speed_t=list(ts))
    truth = 1000.0 * np.sin(2 * np.pi * 1.5 * t[:-1])
    cubic = np.abs(np.asarray(trace.aligned_speed())[:-1] - truth)
    line = np.abs(np.interp(t[:-1], ts, speed) - truth)
    assert cubic.max() < 0.2 * line.max()


def test_the_rate_counts_samples_first_to_last():
    assert Trace(t=[1.0, 1.5, 2.0, 3.0]).rate() == pytest.approx(1.5)
    assert Trace(t=[1.0]).rate() == 0.0


@pytest.mark.parametrize("profile_id", ["dsx7e", "sd25"])
def test_a_sample_is_timed_when_the_drive_took_it_or_left_out_of_the_fit(sim_dir, profile_id):
    """A host late before sending a request or after its answer came (a loaded 2-core machine: 5 ms r.m.s. at 2.7 ms
    per sample through the CLI, up to 80 ms) made a sample stamped when the answer came as late, while the drive had
    taken the reading when the request arrived. Each sample is now stamped when its request goes out, and one whose
    exchange overran the line's time is left out of the fit (SD25: speed and torque in two requests)."""
    sim, d, clock = set_up(profile_id, 115200, stalls=HostStalls(0.2, 0.03, 3, 0.002, after_reply=0.5))
    torque_at = d.profile.need_role("torque_feedback", "test").address
    took: list[tuple[float, float]] = []  # (when the drive took a torque reading, that request's wire time)
    read = sim.read

    def timed_read(address: int, count: int) -> list[int]:
        if address <= torque_at < address + count:
            took.append((clock.now(), wire_time(3, count, 115200) + TURNAROUND_S))
        return read(address, count)

    sim.read = timed_read  # type: ignore[method-assign]
    s = Sampler(d, clock, 100.0)
    for _ in range(300):
        s.sample()
    t, _speed, _torque, _position = s.trace.fitted()
    taken = [(when, request) for (when, request), ok in zip(took, s.trace.on_time, strict=True) if ok]
    assert len(taken) == len(t) and 0 < s.trace.late < 0.4 * len(took)
    for stamp, (when, request) in zip(np.asarray(t) + s.t0, taken, strict=True):
        # at most its request, and what the line's own time tolerates (SD25: two requests a sample)
        assert 0.0 <= when - stamp <= request + max(LATE_S, LATE_SHARE * 2 * request) + 1e-9, (stamp, when)


def test_after_a_gap_in_the_fitted_samples_the_drives_position_is_read_at_once(sim_dir):
    """The fit's position is the speed's integral, which cannot cross a stall (a move may run through it): the first
    sample the fit may use after a gap carries the drive's own position."""
    _sim, d, clock = set_up("dsx7e", 115200, stalls=HostStalls(0.05, 0.2, 5, 0.05, after_reply=0.5))
    s = Sampler(d, clock, 100.0)
    for _ in range(400):
        s.sample()
    t = np.asarray(s.trace.t)
    fitted = np.flatnonzero(s.trace.on_time)
    after = [i for a, i in itertools.pairwise(fitted) if t[i] - t[a] > 0.04]
    assert after and all(s.trace.position[i] is not None for i in after)


def test_the_fits_position_is_set_anew_after_each_gap_by_the_drives_readings():
    """A move through a 300 ms stall: the speed's integral misses the 2 rev turned in it; the readings put it back,
    and a stretch with none keeps the offset of the one before it."""
    t = np.concatenate([np.arange(0.0, 0.3, 0.003), np.arange(0.6, 0.9, 0.003), np.arange(0.95, 1.2, 0.003)])
    truth = np.where(t < 0.45, 0.0, 2.0 * 2 * np.pi)  # rad: the axis turned 2 rev inside the first gap
    cum_w = np.zeros_like(t)  # the speed's integral: nothing outside the gaps
    readings = np.full_like(t, np.nan)
    readings[[5, 120]] = truth[[5, 120]]  # one reading before the stall, one after it; none after the second gap
    position = anchored(t, cum_w, readings)
    assert position == pytest.approx(truth)
    assert anchored(t, cum_w, None) is cum_w
