"""Dithered accelerations against a torque read in whole percent (planning.dither, sampling.quantization_floor)."""

from __future__ import annotations

import math

import numpy as np

from servotool.tuning.estimator import InertiaEstimate
from servotool.tuning.planning import DITHER_MIN, dither
from servotool.tuning.sampling import Trace, quantization_floor

RATED_NM = 1.27
J = 2e-4     # kg*m^2


def test_dither_spreads_cycles_over_the_range() -> None:
    factors = [dither(n) for n in range(8)]
    assert factors[0] == 1.0
    assert len(set(factors)) == 8
    assert all(DITHER_MIN <= f <= 1.0 for f in factors)
    assert max(factors) - min(factors) >= 0.8 * (1.0 - DITHER_MIN)


def _trace(accels: list[float]) -> Trace:
    """Out-and-back moves, one per acceleration (rad/s^2), sampled at 20/s, torque read in whole percent."""
    tr, t = Trace(), 0.0
    for k, a in enumerate(accels):
        sign = 1 if k % 2 == 0 else -1
        for phase in (1, -1):
            for i in range(8):
                w = a * 0.05 * (i + 1 if phase > 0 else 8 - i)
                torque = sign * (phase * J * a + 0.1 * RATED_NM) / RATED_NM * 100
                tr.t.append(t)
                tr.speed.append(sign * w * 30 / math.pi)
                tr.torque.append(float(np.round(torque)))
                tr.position.append(None)
                t += 0.05
        for _ in range(2):
            tr.t.append(t)
            tr.speed.append(0.0)
            tr.torque.append(0.0)
            tr.position.append(None)
            t += 0.05
    return tr


def _estimate() -> InertiaEstimate:
    nan = math.nan
    return InertiaEstimate(True, "", J, 0.001 * J, J / 2.6e-5 - 1, 0.0, nan, nan, nan, nan, nan, nan, nan, nan, 10.0,
                           0.5, 20, 100, 0, 3, 0, 10.0)


def test_dithered_accelerations_leave_less_step_error_repeated() -> None:
    same = quantization_floor(_estimate(), _trace([60.0] * 8), 1.0, RATED_NM, 0.02)
    spread = quantization_floor(_estimate(), _trace([60.0 * dither(n) ** -1 for n in range(8)]), 1.0, RATED_NM, 0.02)
    assert spread.j_std_kgm2 < 0.6 * same.j_std_kgm2
    assert same.j_std_kgm2 > 0.001 * J * 1.5      # the repeated step error is in the uncertainty
