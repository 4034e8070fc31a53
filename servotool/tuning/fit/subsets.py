"""Model check: J compared across subsets of the fit's windows. The rigid model says one J fits every subset;
backlash, compliance and loads that vary make them disagree.

J is taken from each subset with the friction and load fitted on all windows, for three groupings: accelerating and
braking in each direction, the start, middle and end of the travel, and weak, medium and strong accelerations.
Where a grouping's subsets disagree more than their uncertainties allow, the uncertainty is widened by the Birge
ratio sqrt(chi2/dof); where they disagree grossly, the result is refused. Backlash the lost-motion check misses
shows as a lower J while braking or a higher one at weak accelerations, a compliant coupling as J that differs
between the phases of a move.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from servotool.tuning.fit.regression import FitData
from servotool.tuning.fit.verdict import Cause, Verdict

MIN_SUBSET_WINDOWS = 6
MIN_SUBSET_SHARE = 0.02  # a subset with less of the speed changes' information gives no J of its own
BIRGE_WIDEN = 1.5  # subsets that disagree more than this many times their uncertainties widen it (below that:
#                    chance, since a chi2/dof of 2.25 over 2-3 subsets is common on a rigid load) ...
BIRGE_REFUSE = 3.0  # ... refuse where they disagree this many times beyond their uncertainties ...
GROSS_SPREAD = 0.08  # ... and their spread exceeds this fraction of J
ACCEL_SNR = 10.0  # windows sorted by acceleration: their speed change this many times its noise or more,
ACCEL_STEPS = 10.0  # ... and their acceleration torque this many steps of the torque reading or more
ACCEL_BLAME_BIRGE = 3.0  # ... and they disagree this many times their uncertainties before backlash (or, in any
#                          grouping, a mechanism) is blamed (by chance over three unbiased subsets: p ~ 1e-4),
ACCEL_BLAME_SPREAD = 0.05  # ... and by more than this fraction of J (points_off_model)
BLAME_SPREAD = 0.03  # subsets of any grouping that differ by less than this fraction of J blame nothing


def check(v: Verdict) -> Verdict:
    """The uncertainty widened by the worst grouping's disagreement, with its words: refused where gross, an
    off-model note where it points to the mechanics, else a note that it is too small to."""
    fit = v.fit
    birge, spread, name = worst_subsets(fit, fit.x[:, 0], v.j, v.j_std, v.resid)
    if birge <= BIRGE_WIDEN:
        return v
    j_std = v.j_std * birge
    text = f"inertia differs {name} by {100 * spread:.0f} % ({birge:.1f}x its uncertainty)"
    if birge > BIRGE_REFUSE and spread > GROSS_SPREAD:
        return replace(v, j_std=j_std, refuse="; ".join([*(c.words for c in v.fitted), f"{text}: {cause(name)}"]))
    if not points_off_model(name, birge, spread):
        note = f"uncertainty widened {birge:.1f}x: J differs {name} by {100 * spread:.0f} %, {unblamed(name)}"
        widening = Cause(text, curable=True)
    else:
        note = f"off-model: {text}; uncertainty widened to the spread ({cause(name)})"
        widening = Cause(f"{text}; {cause(name)}", curable=False)
    return replace(v, j_std=j_std, widening=widening, remarks=(*v.remarks, note))


def worst_subsets(fit: FitData, dw: np.ndarray, j: float, j_std: float, resid: np.ndarray) -> tuple[float, float, str]:
    """(Birge ratio, relative spread, grouping's name) of the grouping whose subsets disagree most; (1, 0, '')
    where none disagrees beyond chance."""
    worst: tuple[float, float, str] = (1.0, 0.0, "")
    dw_var = float(fit.eiv[0]) * float(fit.x[:, 0] @ fit.x[:, 0])  # fit.eiv is per row of the unit-norm column
    for name, labels in _groupings(fit, dw, j).items():
        birge, spread = _birge(j, j_std, dw, resid, labels, dw_var)
        if birge > worst[0]:
            worst = (birge, spread, name)
    return worst


def cause(name: str) -> str:
    """The mechanics that a disagreement within the named grouping points to, in words."""
    if "acceleration" in name:
        return (
            "backlash (lost motion where the torque reverses) or a compliant coupling: a rigid load weighs the "
            "same at any acceleration"
        )
    if "braking" in name:
        return "backlash (lost motion at reversals) or a compliant coupling (resonance) outside the rigid model"
    if "travel" in name:
        return "the load varies over the travel (gravity on an arm, cogging, a binding guide)"
    return "the load is not one rigid inertia (compliance, backlash or a load that varies)"


def points_off_model(name: str, birge: float, spread: float) -> bool:
    """Whether subsets that disagree this much (Birge ratio, relative spread of J) point to mechanics outside the
    rigid model. No grouping blames them for a spread within BLAME_SPREAD, a difference no setting depends on (a
    rigid load's loop transients make its travel or phases differ that much), nor within ACCEL_BLAME_BIRGE of their
    uncertainties: three subsets of a rigid load disagree beyond 1.5x by chance about one run in ten (the README's
    own tune run once said "off-model: inertia differs over the travel"). An acceleration grouping also needs
    ACCEL_BLAME_SPREAD: a rigid load's weakest accelerations (where a ramp starts and ends) read J up to 3 % apart
    from its strong ones, a bias that a long log makes stand out in sigmas (115200 baud, 0.2 % noise: 1.5-3x)
    though its spread stays small."""
    if spread <= BLAME_SPREAD or birge <= ACCEL_BLAME_BIRGE:
        return False
    return spread > ACCEL_BLAME_SPREAD or "acceleration" not in name


def unblamed(name: str) -> str:
    """The note's words for the named grouping's disagreement that points to no mechanics (points_off_model False).
    A refusal for it names no mechanism either: one that listed "backlash or a compliant coupling, or neither" for a
    disagreement a rigid load shows by chance sent the engineer to look for play that is not there."""
    if "acceleration" in name:
        return "within what a rigid load's weakest accelerations show"
    return "too little to point to the mechanics"


def _groupings(fit: FitData, dw: np.ndarray, j: float) -> dict[str, np.ndarray]:
    """Subsets of the windows to compare J across, by name (as in 'inertia differs NAME'); label -1: left out."""
    sgn = np.sign(fit.w[fit.starts])
    phase = np.where(sgn * dw > 0, 0, 1)  # accelerating, braking
    mid = 0.5 * (fit.position[fit.starts] + fit.position[fit.ends])
    return {
        "between accelerating and braking, forward and reverse": (sgn > 0) * 2 + phase,
        "over the travel (start, middle, end)": _terciles(mid),
        "with the acceleration (weak, medium, strong)": _acceleration_terciles(fit, dw, j),
    }


def _terciles(v: np.ndarray) -> np.ndarray:
    """Each value's third of the range of values (0, 1, 2)."""
    return np.searchsorted(np.quantile(v, [1 / 3, 2 / 3]), v) if v.size else np.zeros(0, dtype=int)


def _acceleration_terciles(fit: FitData, dw: np.ndarray, j: float) -> np.ndarray:
    """Terciles of the windows' accelerations, each read from the speed samples just outside the window
    (outer_speed_change: not the window's own speed change, whose noise would sort itself), of the windows whose
    speed change so read stands ACCEL_SNR times above the noise of a window's own and whose acceleration torque
    spans ACCEL_STEPS steps of the torque reading (-1: the others, and a window with no sample on either side).

    Backlash makes the weakly accelerating windows read J high, where the torque reverses. Sorted by its own speed
    change, a window whose noise shrank it lands among the weak ones and reads J high, and one whose noise grew it
    among the strong ones reading J low: on a rigid load with 1 % speed noise the terciles read J +3..+6 % and
    -2..-5 % in every run, more sigmas the longer the log. Sorted by an acceleration whose noise is not the
    window's, they agree within their uncertainties. A coarse torque reading misreads a weak acceleration's torque
    by a larger share: only windows that span ACCEL_STEPS of its steps are sorted."""
    key = outer_speed_change(fit)
    noise = float(np.sqrt(float(fit.eiv[0]) * float(fit.x[:, 0] @ fit.x[:, 0])))  # of a window's speed change
    accel_torque = abs(j) * np.abs(key) / (fit.t[fit.ends] - fit.t[fit.starts])
    step_nm = fit.torque_step_pct / 100.0 * fit.rated_nm
    clear = np.isfinite(key) & (np.abs(key) >= ACCEL_SNR * noise) & (accel_torque >= ACCEL_STEPS * step_nm)
    labels = np.full(dw.size, -1)
    if np.count_nonzero(clear) >= 3 * MIN_SUBSET_WINDOWS:
        labels[clear] = _terciles(np.abs(key)[clear])
    return labels


def outer_speed_change(fit: FitData) -> np.ndarray:
    """Each window's speed change as read from the samples one before its start and one after its end, scaled to
    its own span (rad/s; NaN for a window at either end of the log): their noise is independent of the window's
    own end samples', which its regressor and residual carry."""
    starts, ends, t, w = fit.starts, fit.ends, fit.t, fit.w
    inside = (starts >= 1) & (ends <= w.size - 2)
    before, after = np.where(inside, starts - 1, starts), np.where(inside, ends + 1, ends)
    return np.where(inside, (w[after] - w[before]) * (t[ends] - t[starts]) / (t[after] - t[before]), np.nan)


@dataclass(frozen=True)
class SubsetJ:
    """J from one subset of the windows, the other parameters held at the whole fit's."""

    label: int
    j: float
    j_std: float  # the whole fit's, scaled by the share of the speed changes' information (sum dw^2) it carries
    windows: int


def subset_js(
    dw: np.ndarray,
    j: float,
    j_std: float,
    resid: np.ndarray,
    labels: np.ndarray,
    min_windows: int = MIN_SUBSET_WINDOWS,
    dw_var: float = 0.0,
) -> list[SubsetJ]:
    """J of each subset (label >= 0) that has min_windows windows and MIN_SUBSET_SHARE of the information, from the
    regressor dw and residual of the model used, corrected for the speed noise as the whole fit is (dw_var: the
    noise variance of a window's speed change): (J * sum(dw^2) + sum(dw * residual)) / (sum(dw^2) - n * dw_var)
    over its n windows. Uncorrected, a subset of weak speed changes reads J low by about dw_var / mean(dw^2) (5-7 %
    in the weakest third of a 115200 baud log's one-interval windows), which the whole fit's correction removes
    only on average over all windows."""
    total = float(dw @ dw)
    out = []
    for label in np.unique(labels[labels >= 0]):
        m = labels == label
        info = float(dw[m] @ dw[m])
        count = int(np.count_nonzero(m))
        noise = count * dw_var
        if count < min_windows or info <= MIN_SUBSET_SHARE * total or info <= 2.0 * noise:
            continue
        sub_j = (j * info + float(dw[m] @ resid[m])) / (info - noise)
        out.append(SubsetJ(int(label), sub_j, j_std * math.sqrt(total / info), count))
    return out


def _birge(
    j: float, j_std: float, dw: np.ndarray, resid: np.ndarray, labels: np.ndarray, dw_var: float
) -> tuple[float, float]:
    """(Birge ratio, relative spread) of J taken from each subset (label >= 0) with the other parameters held."""
    found = subset_js(dw, j, j_std, resid, labels, dw_var=dw_var)
    if len(found) < 2 or not (0 < j_std < math.inf) or not math.isfinite(j):  # an unbounded fit: refused elsewhere
        return 1.0, 0.0
    a, s = np.asarray([f.j for f in found]), np.asarray([f.j_std for f in found])
    wts = 1.0 / s**2
    mean = float(np.sum(wts * a) / np.sum(wts))
    chi2 = float(np.sum(wts * (a - mean) ** 2))
    return math.sqrt(chi2 / (a.size - 1)), float(np.ptp(a)) / abs(j)
