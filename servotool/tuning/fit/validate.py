"""First stage of the fit: is the log well formed, and is it worth fitting?

Malformed input (shapes, non-finite values, time that does not increase, motor data) is a programming error and
raises ValueError; a log that is well formed but too short or saturated is refused in words, as every later stage
refuses.
"""

from __future__ import annotations

import math

import numpy as np

from servotool.tuning.fit.estimate import EstimatorSettings, Partial, Refused


def validate_log(
    t: np.ndarray, rpm: np.ndarray, pct: np.ndarray, rated: float, rotor: float, limit: float | None
) -> None:
    """Raise ValueError for a malformed log (shapes, non-finite values, time not increasing) or motor data."""
    if t.ndim != 1 or t.shape != rpm.shape or t.shape != pct.shape:
        raise ValueError(
            f"t, speed and torque must be 1-D arrays of equal length (got {t.shape}, {rpm.shape}, {pct.shape})"
        )
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(rpm)) and np.all(np.isfinite(pct))):
        raise ValueError("t, speed and torque must be finite (drop samples with failed reads instead of NaN)")
    if t.size > 1 and np.any(np.diff(t) <= 0):
        raise ValueError("sample times must be strictly increasing")
    if not (math.isfinite(rated) and rated > 0):
        raise ValueError(f"rated torque must be a positive number of N*m, got {rated!r}")
    if not (math.isfinite(rotor) and rotor > 0):
        raise ValueError(f"rotor inertia must be a positive number of kg*cm^2, got {rotor!r}")
    if limit is not None and not (math.isfinite(limit) and limit > 0):
        raise ValueError(f"torque limit must be a positive % of rated torque, got {limit!r}")


def check_samples(r: Partial, pct: np.ndarray, torque_limit_pct: float | None, cfg: EstimatorSettings) -> None:
    """Refuse too few samples, and more samples at the torque limit than allowed (a saturated drive no longer
    follows the test motion); counts the saturated samples in r."""
    if r.n_samples < cfg.min_samples:
        raise Refused(f"too few samples ({r.n_samples} < {cfg.min_samples}); log a longer motion or sample faster")
    if torque_limit_pct is not None:
        r.n_saturated = int(np.count_nonzero(np.abs(pct) >= cfg.saturation_fraction * torque_limit_pct))
        if r.n_saturated > cfg.max_saturated_samples:
            raise Refused(
                f"torque saturated: {r.n_saturated} samples at the {torque_limit_pct:g} % torque limit; "
                "use gentler acceleration or a lower test speed"
            )
