"""The score's figures on synthetic legs, and the verdict only beyond the spread."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servotool.tuning.fit.score import Figure, LegSamples, Score, combine, compare, score_run
from servotool.tuning.fit.spectrum import spectrum

RATED = 3000.0
LSB = {"speed": 1.0, "torque": 0.1}


def _step(overshoot: float, ring_hz: float, rate: float = 400.0, decay_s: float = 0.08) -> LegSamples:
    """A 200 rpm step reached in 20 ms that overshoots by `overshoot` (share) and rings at ring_hz."""
    t = np.concatenate(([0.0], np.arange(1, int(0.5 * rate)) / rate))
    rise = np.clip(t / 0.02, 0, 1)
    ring = overshoot * np.exp(-(t - 0.02).clip(0) / decay_s) * np.sin(2 * math.pi * ring_hz * (t - 0.02).clip(0))
    v = 200.0 * (rise + ring)
    v[0] = 0.0
    return LegSamples(1, 1.0, tuple(t), tuple(v), tuple(np.full(t.size, 10.0)), 0.0)


def test_overshoot_settling_and_ringing_are_found_with_their_resolution():
    s = score_run([_step(0.3, 25.0)], 200.0, RATED, LSB)
    f = s.figures
    assert f["overshoot"].value == pytest.approx(30.0 * math.exp(-0.01 / 0.08), abs=3.0)
    assert f["overshoot"].resolution > 0
    assert 0.1 < f["settling"].value / 1000.0 < 0.3
    assert f["settling"].resolution == pytest.approx(2.5, abs=0.1)  # one sample interval, ms
    assert f["ringing"].value == pytest.approx(25.0, abs=f["ringing"].resolution)
    assert f["torque_rms"].value == pytest.approx(10.0)
    assert s.nyquist_hz == pytest.approx(200.0, rel=0.01)


def test_a_ringing_above_the_nyquist_limit_is_not_named():
    s = score_run([_step(0.3, 180.0, rate=100.0)], 200.0, RATED, LSB)
    assert s.nyquist_hz == pytest.approx(50.0, rel=0.02)
    assert s.figures["ringing"].value is None or s.figures["ringing"].value < s.nyquist_hz


def test_the_spectrum_says_its_limit_and_marks_peaks_near_it_unresolved():
    t = np.arange(400) / 100.0
    found = spectrum(t, np.sin(2 * math.pi * 12.0 * t) + 0.5 * np.sin(2 * math.pi * 47.0 * t))
    assert found is not None and found.nyquist_hz == pytest.approx(50.0)
    by_hz = {round(p.hz): p for p in found.peaks}
    assert by_hz[12].resolvable and not by_hz[47].resolvable
    assert by_hz[12].amplitude == pytest.approx(1.0, rel=0.1)


def _score(runs: int = 3, **values: tuple[float | None, float]) -> Score:
    figures = {name: Figure(v, spread, 0.0) for name, (v, spread) in values.items()}
    return Score(figures, runs, 100.0, 50.0)


def test_a_difference_within_the_spread_is_unchanged_and_beyond_it_better_or_worse():
    a = _score(iae=(0.100, 0.010), overshoot=(20.0, 1.0))
    assert compare(a, _score(iae=(0.080, 0.010), overshoot=(20.5, 1.0)))[1] == "unchanged"  # 0.02 < 2 * 0.014
    assert compare(a, _score(iae=(0.050, 0.010), overshoot=(20.5, 1.0)))[1] == "better"
    assert compare(a, _score(iae=(0.050, 0.010), overshoot=(30.0, 1.0)))[1] == "worse"  # one worse spoils it


def test_a_response_that_no_longer_settles_is_worse():
    diffs, overall = compare(_score(settling=(80.0, 2.0)), _score(settling=(None, 0.0)))
    assert overall == "worse" and diffs[0].verdict == "worse"


def test_repeats_give_mean_and_spread():
    runs = [_score(1, iae=(x, 0.0)) for x in (0.1, 0.2, 0.3)]
    both = combine(runs)
    assert both.figures["iae"].value == pytest.approx(0.2) and both.figures["iae"].spread == pytest.approx(0.1)
    assert both.runs == 3
