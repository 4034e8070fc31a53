"""A stopped axis is at rest only when its speed stays inside the band, not when one reading falls inside it."""

from __future__ import annotations

from servotool.motion.rest import SETTLE_S, RestWatch


def test_a_swing_through_zero_is_not_rest():
    watch = RestWatch(8.0)
    assert not any(watch.at_rest(t, v) for t, v in [(0.000, -59.0), (0.010, 2.0), (0.020, 123.0), (0.030, 40.0)])


def test_the_speed_inside_the_band_long_enough_is_rest():
    watch = RestWatch(8.0)
    readings = [(0.000, 30.0), (0.004, 5.0), (0.008, -3.0), (0.012, 4.0), (0.016, -2.0), (0.004 + SETTLE_S, 1.0)]
    assert [watch.at_rest(t, v) for t, v in readings] == [False] * 5 + [True]


def test_two_readings_are_needed_however_far_apart():
    """A slow line (15 readings/s): one reading in the band is not enough, the next one inside it is."""
    watch = RestWatch(8.0)
    assert not watch.at_rest(0.0, 3.0)
    assert watch.at_rest(0.067, -4.0)
