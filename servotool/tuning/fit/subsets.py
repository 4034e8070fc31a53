"""J compared across subsets of the fit's windows (tuning.fit.checks): the rigid model says one J fits every
subset; backlash, compliance and loads that vary make them disagree."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

MIN_SUBSET_WINDOWS = 6
ACCEL_SNR = 10.0  # windows sorted by acceleration: their speed change this many times its noise or more,
ACCEL_STEPS = 10.0  # ... and their acceleration torque this many steps of the torque reading or more
NOISE_BIRGE = 3.0  # ... and they disagree this many times their uncertainties before backlash is blamed,
NOISE_SPREAD = 0.05  # ... and by more than this fraction of J (points_off_model)
BLAME_SPREAD = 0.03  # subsets of any grouping that differ by less than this fraction of J blame nothing


@dataclass(frozen=True)
class Windows:
    """The fit's samples and windows, as the subsets need them."""

    t: np.ndarray
    w: np.ndarray  # rad/s
    position: np.ndarray  # rad
    starts: np.ndarray
    ends: np.ndarray
    eiv: float  # the speed change's noise variance, scaled as the fit's first column (FitData.eiv[0])
    torque_step: float  # N*m: the torque reading's resolution where it reads on a grid (0: finer or unknown)


def worst_subsets(win: Windows, dw: np.ndarray, j: float, j_std: float, resid: np.ndarray) -> tuple[float, float, str]:
    """(Birge ratio, relative spread, grouping's name) of the grouping whose subsets disagree most; (1, 0, '')
    where none disagrees beyond chance."""
    worst: tuple[float, float, str] = (1.0, 0.0, "")
    for name, labels in _groupings(win, dw, j).items():
        birge, spread = _birge(j, j_std, dw, resid, labels)
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
    rigid model, or may be the speed noise: windows sorted by their own speed change sort its noise too, and the
    weak ones read J high on a rigid load. The artefact is a bias, so with many windows it stands out in sigmas
    (rigid loads, acceleration grouping beyond 1.5: 48 % of 60 runs at 115200; 3.3-4.9 sigmas on the simulated
    drive's 2000 samples/s) though its spread stays small (at most 3.9 % of J there), and with few it spreads far
    but within its sigmas (DSX7E at 19200: 5.8-11.6 % at 1.5-3). Such a grouping's disagreement still widens the
    uncertainty; it blames the mechanics only beyond both NOISE_BIRGE and NOISE_SPREAD. No grouping blames them for
    a spread within BLAME_SPREAD: on thousands of windows a rigid load's travel or phases differ by 1 % at 1.5-5
    sigmas (the loop's own transients), a difference no setting depends on."""
    if spread <= BLAME_SPREAD:
        return False
    return (birge > NOISE_BIRGE and spread > NOISE_SPREAD) or "acceleration" not in name


def unblamed(name: str) -> tuple[str, str]:
    """(the note's words, the causes a refusal names) for the named grouping's disagreement that points to no
    mechanics (points_off_model False); the causes are empty where it names none."""
    if "acceleration" in name:
        return (
            "as much as the speed noise alone can make it differ on a rigid load",
            "the speed noise, or backlash or a compliant coupling",
        )
    return "too little to point to the mechanics", ""


def _groupings(win: Windows, dw: np.ndarray, j: float) -> dict[str, np.ndarray]:
    """Subsets of the windows to compare J across, by name (as in 'inertia differs NAME'); label -1: left out."""
    sgn = np.sign(win.w[win.starts])
    phase = np.where(sgn * dw > 0, 0, 1)  # accelerating, braking
    mid = 0.5 * (win.position[win.starts] + win.position[win.ends])
    return {
        "between accelerating and braking, forward and reverse": (sgn > 0) * 2 + phase,
        "over the travel (start, middle, end)": _terciles(mid),
        "with the acceleration (weak, medium, strong)": _acceleration_terciles(win, dw, j),
    }


def _terciles(v: np.ndarray) -> np.ndarray:
    """Each value's third of the range of values (0, 1, 2)."""
    return np.searchsorted(np.quantile(v, [1 / 3, 2 / 3]), v) if v.size else np.zeros(0, dtype=int)


def _acceleration_terciles(win: Windows, dw: np.ndarray, j: float) -> np.ndarray:
    """Terciles of the windows' accelerations (their speed changes: every window spans as many sampling intervals,
    and a jittered interval would sort its length in too), of the windows whose speed change stands ACCEL_SNR times
    above its noise (-1: the others).

    Backlash: the motor crosses the gap alone where the torque reverses, and the weakly accelerating windows there
    read J high (+14-18 % where the whole fit was +7-9 % off with a 3 sigma of 5-6 %). Sorting by the speed change
    itself sorts its noise too: a window whose noise shrank it lands among the weak ones and reads J high (+7 % on a
    bare motor with 1 % noise), so only windows the noise cannot move between terciles are sorted. Likewise a
    torque read in whole percent misreads a weak acceleration's torque by a larger share (a bare IS620P motor with
    noise-free readings: J 19 % apart), so only windows whose acceleration torque spans ACCEL_STEPS of its steps."""
    noise = float(np.sqrt(win.eiv * float(dw @ dw)))  # the noise of a window's speed change
    accel_torque = abs(j) * np.abs(dw) / (win.t[win.ends] - win.t[win.starts])
    clear = (np.abs(dw) >= ACCEL_SNR * noise) & (accel_torque >= ACCEL_STEPS * win.torque_step)
    labels = np.full(dw.size, -1)
    if np.count_nonzero(clear) >= 3 * MIN_SUBSET_WINDOWS:
        labels[clear] = _terciles(np.abs(dw)[clear])
    return labels


def _birge(j: float, j_std: float, dw: np.ndarray, resid: np.ndarray, labels: np.ndarray) -> tuple[float, float]:
    """(Birge ratio, relative spread) of J taken from each subset (label >= 0) with the other parameters held."""
    total = float(dw @ dw)
    js, sig = [], []
    for label in np.unique(labels[labels >= 0]):
        m = labels == label
        info = float(dw[m] @ dw[m])
        if np.count_nonzero(m) < MIN_SUBSET_WINDOWS or info <= 0.02 * total:
            continue
        js.append(j + float(dw[m] @ resid[m]) / info)
        sig.append(j_std * math.sqrt(total / info))
    if len(js) < 2 or not (0 < j_std < math.inf) or not math.isfinite(j):  # an unbounded fit: refused elsewhere
        return 1.0, 0.0
    a, s = np.asarray(js), np.asarray(sig)
    wts = 1.0 / s**2
    mean = float(np.sum(wts * a) / np.sum(wts))
    chi2 = float(np.sum(wts * (a - mean) ** 2))
    return math.sqrt(chi2 / (a.size - 1)), float(np.ptp(a)) / abs(j)


def torque_step(torque: np.ndarray) -> float:
    """The torque reading's step (N*m) where every reading lies on one grid (whole percent: SD25, SDC, IS620P), else
    0."""
    values = np.unique(torque)
    if values.size < 3:
        return 0.0
    step = float(np.min(np.diff(values)))
    grid = (values - values[0]) / step
    return step if float(np.max(np.abs(grid - np.round(grid)))) < 0.01 else 0.0
