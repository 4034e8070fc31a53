"""The identification's trace (tuning.sampling): the speed brought onto the torque's times, the sampling rate."""

from __future__ import annotations

import numpy as np
import pytest

from servotool.tuning.sampling import Trace


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
