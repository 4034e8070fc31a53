"""Is the rigid model right for this load? Consistency checks on the inertia fit (tuning.estimator).

Mechanics outside the model (a compliant coupling, backlash, gravity that changes with position, cogging) leave
the fit's noise-based uncertainty tight while the answer is wrong. Two checks see them:

- the load torque over the travel: the fit is repeated with a load torque that varies (quadratically) with the
  position (integrated speed). Where the variation is significant, the load varies over the travel and the
  extended model's inertia is used (an arm on a gear: the constant-torque model biased J by 10-40 %).
- subsets: J is taken from each subset of the windows with the friction and load fitted on all of them
  (forward/reverse x accelerating/braking, and the start/middle/end of the travel). Where the subsets disagree
  more than their uncertainties allow, the uncertainty is widened by the Birge ratio sqrt(chi2/dof); where they
  disagree grossly (by more than GROSS_SPREAD of J, well beyond their uncertainties) the result is refused.
  Backlash shows as a lower J while braking (the motor crosses the gap alone), a compliant coupling as J that
  differs between the phases of a move.

The returned words start with "off-model:" so reports can tell these notes from others.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit_numerics import corrected_lstsq, cumulative_hermite, jackknife_std

POSITION_SIGMA = 4.0      # a position-dependent load term counts when beyond this many sigmas ...
POSITION_MIN_PCT = 2.0    # ... and it changes the load by at least this % of rated torque over the travel
MIN_SUBSET_WINDOWS = 6
BIRGE_REFUSE = 3.0        # refuse when the subsets disagree this many times beyond their uncertainties ...
GROSS_SPREAD = 0.08       # ... and their spread exceeds this fraction of J


@dataclass(frozen=True)
class FitData:
    """What the estimator's fit saw: samples, windows, the regression and its solution (unscaled)."""

    t: np.ndarray
    w: np.ndarray             # rad/s
    kink: np.ndarray
    position: np.ndarray      # rad, integral of w at each sample
    starts: np.ndarray
    ends: np.ndarray
    x: np.ndarray             # columns: J (dw), then friction and load terms
    y: np.ndarray
    eiv: np.ndarray           # regressor-noise variance per row of the column-scaled x
    scale: np.ndarray
    groups: np.ndarray        # move number of each window (for the jackknife)
    theta: np.ndarray
    j_std: float
    min_jackknife_moves: int
    rated_nm: float


@dataclass(frozen=True)
class Verdict:
    j: float
    j_std: float
    notes: tuple[str, ...]
    refuse: str = ""          # empty: usable (perhaps with a widened uncertainty)
    widened: str = ""         # why the uncertainty was widened (words for a refusal it causes), empty if not


def assess(fit: FitData) -> Verdict:
    """J and its uncertainty after the consistency checks, with the operator's words for what was found."""
    j, j_std, resid = float(fit.theta[0]), fit.j_std, fit.y - fit.x @ fit.theta
    notes: list[str] = []
    why = ""
    extended = _position_model(fit)
    if extended is not None:
        j, j_std, resid, change_pct = extended
        why = (f"load varies over the travel (load torque changes by {change_pct:.0f} % of rated torque: an arm or "
               "a gravity axis on a gear?)")
        notes.append(f"off-model: {why}; inertia fitted with a position-dependent load")
    dw = fit.x[:, 0]
    worst: tuple[float, float, str] = (1.0, 0.0, "")
    for name, labels in _groupings(fit, dw).items():
        birge, spread = _birge(j, j_std, dw, resid, labels)
        if birge > worst[0]:
            worst = (birge, spread, name)
    birge, spread, name = worst
    if birge > 1.0:
        j_std *= birge
        text = f"inertia differs {name} by {100 * spread:.0f} % ({birge:.1f}x its uncertainty)"
        if birge > BIRGE_REFUSE and spread > GROSS_SPREAD:
            return Verdict(j, j_std, tuple(notes), refuse=f"{text}: {_cause(name)}")
        if birge > 1.5:
            notes.append(f"off-model: {text}; uncertainty widened to the spread ({_cause(name)})")
            return Verdict(j, j_std, tuple(notes), widened=f"{text}; {_cause(name)}")
    return Verdict(j, j_std, tuple(notes), widened=why)


def _cause(name: str) -> str:
    if "braking" in name:
        return "backlash (lost motion at reversals) or a compliant coupling (resonance) outside the rigid model"
    if "travel" in name:
        return "the load varies over the travel (gravity on an arm, cogging, a binding guide)"
    return "the load is not one rigid inertia (compliance, backlash or a load that varies)"


def _position_model(fit: FitData) -> tuple[float, float, np.ndarray, float] | None:
    """Refit with the load torque quadratic in position; (J, sigma, residual, change in % of rated) when the
    position terms matter, else None."""
    pos = fit.position
    lo, hi = float(np.min(pos)), float(np.max(pos))
    if hi - lo <= 0:
        return None
    u = (pos - 0.5 * (lo + hi)) / (0.5 * (hi - lo))       # -1..1 over the travel
    cols = []
    for p in (u, u * u):
        cum = cumulative_hermite(fit.t, p, fit.kink)
        cols.append(cum[fit.ends] - cum[fit.starts])
    x = np.column_stack([fit.x, *cols])
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    xs = x / scale
    eiv = np.concatenate([fit.eiv, np.zeros(2)])
    try:
        theta = corrected_lstsq(xs, fit.y, eiv) / scale
    except np.linalg.LinAlgError:
        return None
    resid = fit.y - x @ theta
    dof = max(1, x.shape[0] - x.shape[1])
    try:
        cov = float(resid @ resid) / dof * np.linalg.inv(xs.T @ xs - xs.shape[0] * np.diag(eiv))
    except np.linalg.LinAlgError:
        return None
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / scale
    std = np.maximum(std, jackknife_std(xs, fit.y, eiv, fit.groups, fit.min_jackknife_moves) / scale)
    a1, a2 = theta[-2], theta[-1]
    s1, s2 = std[-2], std[-1]
    significant = abs(a1) > POSITION_SIGMA * s1 or abs(a2) > POSITION_SIGMA * s2
    grid = np.linspace(-1.0, 1.0, 21)
    change_pct = float(np.ptp(a1 * grid + a2 * grid * grid)) / fit.rated_nm * 100
    if not significant or change_pct < POSITION_MIN_PCT or not math.isfinite(std[0]):
        return None
    return float(theta[0]), max(float(std[0]), fit.j_std), resid, change_pct


def _groupings(fit: FitData, dw: np.ndarray) -> dict[str, np.ndarray]:
    """Subsets of the windows to compare J across, by name (as in 'inertia differs NAME')."""
    sgn = np.sign(fit.w[fit.starts])
    phase = np.where(sgn * dw > 0, 0, 1)                      # accelerating, braking
    mid = 0.5 * (fit.position[fit.starts] + fit.position[fit.ends])
    edges = np.quantile(mid, [1 / 3, 2 / 3]) if mid.size else np.zeros(2)
    return {
        "between accelerating and braking, forward and reverse": (sgn > 0) * 2 + phase,
        "over the travel (start, middle, end)": np.searchsorted(edges, mid),
    }


def _birge(j: float, j_std: float, dw: np.ndarray, resid: np.ndarray, labels: np.ndarray) -> tuple[float, float]:
    """(Birge ratio, relative spread) of J taken from each subset with the other parameters held."""
    total = float(dw @ dw)
    js, sig = [], []
    for label in np.unique(labels):
        m = labels == label
        info = float(dw[m] @ dw[m])
        if np.count_nonzero(m) < MIN_SUBSET_WINDOWS or info <= 0.02 * total:
            continue
        js.append(j + float(dw[m] @ resid[m]) / info)
        sig.append(j_std * math.sqrt(total / info))
    if len(js) < 2 or j_std <= 0:
        return 1.0, 0.0
    a, s = np.asarray(js), np.asarray(sig)
    wts = 1.0 / s**2
    mean = float(np.sum(wts * a) / np.sum(wts))
    chi2 = float(np.sum(wts * (a - mean) ** 2))
    return math.sqrt(chi2 / (a.size - 1)), float(np.ptp(a)) / abs(j)
