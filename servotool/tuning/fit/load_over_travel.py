"""Model check: a load torque that varies over the travel (an arm's gravity through a gear, a binding guide). The
rigid model's constant load torque then biases J; this check fits a load that varies (quadratically) with the
position and takes J from it where the variation is significant.

Backlash also looks like such a load, and the extended model then moves J the wrong way: where the dependence
differs between forward and reverse moves (gravity on an arm is the same function of the position both ways, lost
motion at the reversals is not), half its correction counts as uncertain.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from servotool.tuning.fit.regression import FitData, refit
from servotool.tuning.fit.signals import cumulative_hermite
from servotool.tuning.fit.verdict import Cause, Verdict, take

POSITION_SIGMA = 4.0  # a position-dependent load term counts when beyond this many sigmas ...
POSITION_MIN_PCT = 2.0  # ... and is named where it changes the load by at least this % of rated torque over the
#                         travel (short of that it widens J's uncertainty by what it would change J)
POSITION_MODEL_ERROR = 0.5  # half the model's correction counts as uncertain where its load differs between the
#                             directions (backlash looks like a load that varies over the travel) ...
ONE_WAY_SIGMA = 2.0  # ... by more than this many sigmas


def check(v: Verdict) -> Verdict:
    """J from the model with a load that varies over the travel, where that variation is significant and large
    enough to name; where it is significant but small (a short travel over which an arm's gravity changes little),
    J's uncertainty widened by what the model would change J: DSX7E at 115200 baud and 2 rev, an arm of 10 %
    through a gear of 10, was accepted 6-7 % low with no note, its term at 9 sigma but its change under 2 %."""
    position = _position_model(v.fit)
    if position is None:
        return v
    cols, change_pct, one_way, named = position
    x = np.column_stack([v.x, cols])
    if not named:
        hinted = take(v.fit, x, (v.j, v.j_std, v.resid), 0.0)
        return replace(v, j_std=math.hypot(v.j_std, hinted[0] - v.j))
    cause = (
        f"load varies over the travel (load torque changes by {change_pct:.0f} % of rated torque: an arm or a gravity "
        "axis on a gear?)"
    )
    j, j_std, resid = take(v.fit, x, (v.j, v.j_std, v.resid), POSITION_MODEL_ERROR if one_way else 0.0)
    return replace(v, x=x, j=j, j_std=j_std, resid=resid, fitted=(*v.fitted, Cause(cause, curable=False)))


def _position_model(fit: FitData) -> tuple[np.ndarray, float, bool, bool] | None:
    """(the two position columns, the load's change over the travel in % of rated, whether it differs between the
    directions, whether it changes the load enough to name) when the load torque varies significantly with
    position, else None."""
    cols = _position_columns(fit)
    if not np.any(cols[0]):
        return None
    found = refit(fit, np.column_stack([fit.x, *cols]))
    if found is None:
        return None
    theta, std, _resid = found
    a1, a2 = theta[-2], theta[-1]
    z = max(abs(a1) / std[-2], abs(a2) / std[-1]) if std[-2] > 0 and std[-1] > 0 else math.inf
    grid = np.linspace(-1.0, 1.0, 21)
    change_pct = float(np.ptp(a1 * grid + a2 * grid * grid)) / fit.rated_nm * 100
    if not z > POSITION_SIGMA or not math.isfinite(std[0]):
        return None
    named = change_pct >= POSITION_MIN_PCT
    return np.column_stack(cols), change_pct, named and _one_way(fit, cols), named


def _position_columns(fit: FitData) -> list[np.ndarray]:
    """Window integrals of the position (scaled to -1..1 over the travel) and its square."""
    pos = fit.position
    lo, hi = float(np.min(pos)), float(np.max(pos))
    u = (pos - 0.5 * (lo + hi)) / (0.5 * (hi - lo)) if hi > lo else np.zeros_like(pos)
    cols = []
    for p in (u, u * u):
        cum = cumulative_hermite(fit.t, p, fit.kink, fit.cut)
        cols.append(cum[fit.ends] - cum[fit.starts])
    return cols


def _one_way(fit: FitData, cols: list[np.ndarray]) -> bool:
    """Whether the position dependence differs between forward and reverse moves: gravity on an arm is the same
    function of the position both ways, lost motion at the reversals (backlash) is not."""
    sgn = np.sign(fit.w[fit.starts])
    found = refit(fit, np.column_stack([fit.x, *cols, *(c * sgn for c in cols)]))
    if found is None:
        return True
    theta, std = found[0], found[1]
    return bool(np.any(np.abs(theta[-2:]) > ONE_WAY_SIGMA * std[-2:]))
