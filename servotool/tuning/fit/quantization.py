"""Model check: the floor the torque reading's steps set on J's uncertainty, which no fit sees.

A torque read in coarse steps (whole percent) that stays on one value while the axis accelerates misreads the torque
by the same amount in every such sample: an error that repeats move after move, which neither the least-squares
spread nor the jackknife sees. Readings that move between steps (noise, a torque that varies) average it out. J
follows the difference between accelerating and braking torque (the friction and load terms take up what is
common): the floor is (q / sqrt 12) / 2 x the share of moving samples that read as their neighbour, over the RMS
acceleration torque. The part that differs between moves (dithered accelerations) counts too, as a move's misreading
averaged over the moves: the adaptive repeats stop as soon as the jackknife happens to look small enough.

The floor is added last (fit.conclude): a result refused for another reason keeps the fit's own uncertainty, and a
refusal names the reading's steps only where they alone took it over the limit.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from servotool.tuning.fit.verdict import Floor, Verdict


def check(v: Verdict) -> Verdict:
    """The verdict with the floor the torque reading's step sets on the J it settled on (unchanged where none)."""
    fit = v.fit
    found = floor(fit.t, fit.rpm, fit.pct, v.j, fit.torque_step_pct, fit.rated_nm)
    return v if found is None else replace(v, floor=found)


def floor(t: np.ndarray, rpm: np.ndarray, pct: np.ndarray, j: float, step_pct: float, rated_nm: float) -> Floor | None:
    """The relative uncertainty of J (kg*m^2) that a torque reading in steps of step_pct (% of rated) leaves in a log
    (t s, rpm, pct % of rated); None where the reading has no step, the log is too short or the floor is zero."""
    if step_pct <= 0 or t.size < 4:
        return None
    moving = np.abs(rpm) > 0.05 * float(np.max(np.abs(rpm)))
    pair = moving[1:] & moving[:-1]
    if np.count_nonzero(pair) < 4:
        return None
    accel = np.diff(rpm)[pair] / np.diff(t)[pair] * np.pi / 30.0  # rad/s^2
    signal_pct = j * float(np.sqrt(np.mean(accel**2))) / rated_nm * 100.0
    stuck = float(np.mean(np.diff(pct)[pair] == 0.0))
    share, moves = _repeated_share(moving, pair, accel, j / rated_nm * 100.0, step_pct)
    rel_q = relative_floor(step_pct, stuck, signal_pct, share, moves)
    return Floor(rel_q, step_pct, signal_pct) if rel_q > 0 else None


def relative_floor(step_pct: float, stuck: float, signal_pct: float, share: float, moves: int) -> float:
    """The floor (relative to J) of a torque read in steps of step_pct against an RMS acceleration torque of
    signal_pct, where `stuck` of the moving samples read as their neighbour, `share` of one move's misreading repeats
    in every move, over `moves` moves (tuning.budget plans with the same)."""
    misread = step_pct / 12**0.5 * stuck / max(signal_pct, 1e-9)  # one reading's, relative to the signal
    return math.hypot(misread / 2.0 * share, misread / 2**0.5 / max(moves, 1) ** 0.5)


def repeated_share(spread_steps: float) -> float:
    """The share of one move's misreading that every move repeats, for moves whose acceleration torques spread
    evenly over spread_steps steps of the reading (see _repeated_share)."""
    return max(1.0 - spread_steps, 0.3 / max(spread_steps, 1.0))


def _repeated_share(
    moving: np.ndarray, pair: np.ndarray, accel: np.ndarray, pct_per_accel: float, step_pct: float
) -> tuple[float, int]:
    """The share of the step error that every move repeats, and the number of moves it counts. Moves whose
    acceleration torques spread evenly over a range s (in reading steps) misread it by the sawtooth's values over
    that range: their common part has, over the unknown offset, an RMS of (1 - s) of one move's for s <= 1 and at
    most 0.17 of it beyond (none at whole steps); the part that differs between moves is the jackknife's (and
    the floor's). Without dithered ramps s is ~0: one."""
    run = np.cumsum(np.concatenate(([0], (moving[1:] & ~moving[:-1]).astype(int))))[1:][pair]
    levels = [
        float(np.sqrt(np.mean(accel[run == k] ** 2))) * pct_per_accel
        for k in np.unique(run)
        if np.count_nonzero(run == k) >= 2
    ]
    # The pilot's weak moves carry little weight in the fit (and would stretch the range): left out.
    strong = [v for v in levels if v >= 0.5 * max(levels, default=0.0)]
    if len(strong) < 4:
        return 1.0, len(strong)
    return repeated_share((max(strong) - min(strong)) / step_pct), len(strong)
