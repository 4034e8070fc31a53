"""A stopped axis is at rest only when its speed stays inside the band, not when one reading falls inside it, and
when the mean of enough readings is near zero."""

from __future__ import annotations

import random

import pytest

from servotool.motion.rest import SETTLE_S, STOPPED_RPM, RestWatch, band_of


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


def test_a_slow_turn_inside_a_wide_band_is_not_rest():
    """A gravity axis held at 38 rpm read with 10 rpm noise: every reading is inside the band of four noises (41
    rpm), and the servo-off let it go. The mean of the readings the noise calls for tells it from rest."""
    rng = random.Random(1)
    watch = RestWatch(41.0)
    assert watch.readings_needed >= 9
    assert not any(watch.at_rest(i * 0.04, 38.0 + rng.gauss(0, 10) * 0.2) for i in range(100))
    assert watch.mean_rpm == pytest.approx(38.0, abs=2.0)


def test_noise_around_zero_is_rest_once_the_mean_has_its_readings():
    rng = random.Random(2)
    watch = RestWatch(41.0)
    rested = [watch.at_rest(i * 0.04, rng.gauss(0, 10)) for i in range(40)]
    assert rested.index(True) >= watch.readings_needed - 1
    assert abs(watch.mean_rpm) < 10.0


def test_a_band_of_a_noise_free_reading_keeps_two_readings():
    assert RestWatch(STOPPED_RPM).readings_needed == 2
    assert band_of(0.0) == STOPPED_RPM and band_of(10.0) == 40.0
