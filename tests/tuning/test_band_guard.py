"""The travel band's guard (tuning.band_guard): an own segment bounded by the room the band leaves it."""

from __future__ import annotations

import pytest

from servotool.tuning.band_guard import BandGuard

BAND = (-0.1, 1.7)


def _ends_inside(guard: BandGuard, pred: float, direction: int, speed: float, full: float) -> tuple[float, float]:
    """(the segment own_room allows, where begin then predicts it to end); must_stop leaves it to the drive."""
    own = guard.own_room(pred, direction, speed, full)
    assert own is not None
    guard.begin(pred, direction, speed, own, full)
    assert guard.own_end is not None
    assert not guard.must_stop(pred, 0.0, 0.1, 0.005)  # predicted inside the band: no stop command to wait for
    return own, guard.own_end


def test_a_segment_that_fits_keeps_its_length_and_one_that_does_not_is_cut_to_end_at_the_band():
    # run past their segments 0.05 s at speed before (load 37's under-damped loop: 0.4-0.5 rev at 550-650 rpm)
    guard = BandGuard(band=BAND, stretch=1.48, own_lag_s=0.05)
    assert guard.own_room(0.0, 1, 300.0, 0.5) == 0.5  # 0.5 + 2 x 0.05 s x 5 rev/s = 1.0 rev: inside
    own, end = _ends_inside(guard, 0.59, 1, 558.0, 0.93)  # the move that ran to 1.99 rev at e2d253e
    assert own < 0.93 and end == pytest.approx(BAND[1])
    assert guard.own_peak == pytest.approx(558.0 * (own / 0.93) ** 0.5)  # a shorter segment peaks lower
    own, end = _ends_inside(guard, 0.98, -1, 558.0, 0.93)
    assert own < 0.93 and end == pytest.approx(BAND[0])


def test_before_any_segment_ran_past_its_end_the_pilots_stretch_sizes_it_and_no_room_gives_none():
    guard = BandGuard(band=BAND, stretch=1.5)
    assert guard.own_room(1.0, 1, 600.0, 1.0) == pytest.approx(0.7 / 1.5)
    assert guard.own_room(1.8, 1, 600.0, 1.0) == 0.0  # beyond the band already: nothing more that way
    assert BandGuard().own_room(0.0, 1, 600.0, 1.0) is None  # the pilot: no band yet
