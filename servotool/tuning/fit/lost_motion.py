"""Model check: lost motion (backlash), the first of the checks (fit.checks), since it changes the windows every
later check stands on.

Where the torque through a coupling with backlash reverses (a move's braking after its acceleration, a start against
the flank the last stop left), the motor crosses the gap alone: windows there read J far low, and with them the
friction every window shares. An observer follows the load through a small dead zone behind the measured motor
speed, with the load's inertia and friction from the rigid fit, and marks the sampling intervals in which the motor
and the load may not have turned together; a larger gap's lost motion falls inside the spans it marks too. Where the
windows clear of them (by a margin) give a J apart from the whole fit's, they alone are fitted from there on, with
what a wider margin still changes counted as uncertain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from servotool.tuning.fit.regression import FitData, refit
from servotool.tuning.fit.verdict import Cause, Verdict

GAP_RAD = 0.05  # the dead zone the observer assumes (at the motor shaft)
MARGIN_INTERVALS = 1  # sampling intervals kept clear on both sides of a marked span
STEP_S = 1e-3  # the observer's integration step (a crossing lasts tens of ms)
LOST_MOTION_SIGMA = 3.0  # the windows clear of possible lost motion count where their J is this many sigmas apart
MIN_WINDOWS = 12  # ... and they are at least this many
WORDS = "lost motion (backlash?)"  # how its cause begins


@dataclass(frozen=True)
class LoadSide:
    """The load as the rigid fit sees it: inertia beyond the motor's and what slows it (N*m, N*m*s/rad)."""

    inertia: float
    coulomb: float
    viscous: float
    load_torque: float

    def drag(self, w: float) -> float:
        """The torque that slows the load (positive opposes positive speed); none from Coulomb at standstill."""
        return self.coulomb * _sign(w) + self.viscous * w + self.load_torque


def _sign(v: float) -> int:
    return (v > 0) - (v < 0)


def coupled_intervals(t: np.ndarray, w: np.ndarray, load: LoadSide, gap: float = GAP_RAD) -> np.ndarray:
    """Per sampling interval, whether the motor and the load stayed in contact through all of it (motor speed w
    in rad/s, linear between samples). The load starts in the middle of the gap: where it rests is unknown."""
    half = gap / 2.0
    defl, w_load, contact = 0.0, float(w[0]), False
    out = np.zeros(max(0, t.size - 1), dtype=bool)
    if load.inertia <= 0:
        return ~out
    for i in range(t.size - 1):
        span = float(t[i + 1] - t[i])
        steps = max(1, math.ceil(span / STEP_S))
        dt = span / steps
        w0, accel = float(w[i]), float(w[i + 1] - w[i]) / span
        held = contact
        for k in range(steps):
            w_motor = w0 + accel * (k + 0.5) * dt
            # In contact the flank must push the load along: a torque of the wrong sign lets it go.
            if contact and (load.inertia * accel + load.drag(w_motor)) * _sign(defl) < 0:
                contact = False
            if not contact:
                coasting = w_load - load.drag(w_load) / load.inertia * dt
                if _sign(coasting) != _sign(w_load) and abs(load.load_torque) < load.coulomb:
                    coasting = 0.0  # friction stops the load; it does not turn it back
                w_load = coasting
                defl += (w_motor - w_load) * dt
                if abs(defl) >= half:
                    defl, contact, w_load = math.copysign(half, defl), True, w_motor
            held = held and contact
        out[i] = held
    return out


def clear_windows(
    starts: np.ndarray, ends: np.ndarray, coupled: np.ndarray, margin: int = MARGIN_INTERVALS
) -> np.ndarray:
    """The windows [starts, ends] (sample indices) whose intervals, and margin intervals either side, all stayed
    coupled."""
    loose = np.concatenate(([0], np.cumsum(~coupled)))
    lo = np.clip(starts - margin, 0, coupled.size)
    hi = np.clip(ends + margin, 0, coupled.size)
    return (loose[hi] - loose[lo]) == 0


def check(v: Verdict) -> Verdict:
    """The verdict on the windows clear of lost motion where their J stands apart (clear_of_lost_motion), with its
    cause (curable where a stronger motion shrinks it)."""
    fit, cause = clear_of_lost_motion(v.fit)
    if cause is None:
        return v
    return replace(
        v,
        fit=fit,
        x=fit.x,
        j=float(fit.theta[0]),
        j_std=fit.j_std,
        resid=fit.y - fit.x @ fit.theta,
        fitted=(*v.fitted, cause),
    )


def clear_of_lost_motion(fit: FitData) -> tuple[FitData, Cause | None]:
    """The fit over the windows clear of where the motor may have turned without its load, with its cause, where
    their J stands LOST_MOTION_SIGMA of its uncertainty apart from the whole fit's; else the fit as it is, and none.

    Where they read J higher, the windows left out read it low: the motor crossed the gap alone, which a stronger
    motion does faster (curable: backlash 0.1 rad at ratio 2 and 4 rev). Where they read it lower, the windows left
    out read it high: the flank taking the load up (the same backlash at 7 rev), or a compliant coupling's
    deflection rate, whose torque changes the observer marks too (15-20 Hz couplings at 4 rev: -9..-17 %, named
    lost motion alone and, once a travel was named for it, followed to 20-30 rev and refused again). Both are named
    there, and a stronger motion cures neither. Where the load rests in the gap is unknown, so the first motion
    counts as a crossing: a breakaway there on a rigid load is left out too, hence the question mark."""
    found = clear(fit)
    if found is None or not abs(found.near.theta[0] - fit.theta[0]) > LOST_MOTION_SIGMA * found.near.j_std:
        return fit, None
    if found.near.theta[0] > fit.theta[0]:
        return found.fit, Cause(found.words, curable=True)
    return found.fit, Cause(found.words.replace(WORDS, f"{WORDS} or a compliant coupling", 1), curable=False)


@dataclass(frozen=True)
class Clear:
    """The fit over the windows clear of possible lost motion (fit: its J's uncertainty includes `left`, what a
    wider margin still changes) with its windows (keep, over the whole fit's), and the one at the narrower margin."""

    fit: FitData
    keep: np.ndarray
    left: float
    near: FitData
    words: str


def clear(fit: FitData) -> Clear | None:
    """The fits over the windows clear of where the motor may have turned without its load (the observer following
    the load with the rigid fit's inertia and friction), whether or not their J stands apart; None where that leaves
    too few windows, or all of them. How far J moves again when the windows keep twice as clear is what the
    narrower margin may have left in; with too few windows for that, the whole change counts instead."""
    est = dict(zip(fit.names, (float(v) for v in fit.theta), strict=True))
    load = LoadSide(est["J"] - fit.jm, est["Tc"], est.get("B", 0.0), est.get("Tg", 0.0))
    coupled = coupled_intervals(fit.t, fit.w, load)
    near = _clear_fit(fit, coupled, MARGIN_INTERVALS)
    if near is None:
        return None
    wide = _clear_fit(fit, coupled, 2 * MARGIN_INTERVALS)
    answer = near if wide is None else wide
    left = float(answer.theta[0] - (fit.theta[0] if wide is None else near.theta[0]))
    words = (
        f"{WORDS} where the torque reverses or the axis first moves: J from the "
        f"{answer.starts.size} of {fit.starts.size} windows clear of it"
    )
    keep = clear_windows(fit.starts, fit.ends, coupled, MARGIN_INTERVALS * (1 if wide is None else 2))
    return Clear(replace(answer, j_std=math.hypot(answer.j_std, left)), keep, left, near, words)


def _clear_fit(fit: FitData, coupled: np.ndarray, margin: int) -> FitData | None:
    """The fit refitted over the windows that stay `margin` intervals clear of the intervals not `coupled`; None
    where that leaves too few windows, or all of them."""
    keep = clear_windows(fit.starts, fit.ends, coupled, margin)
    if keep.all() or np.count_nonzero(keep) < max(MIN_WINDOWS, 3 * fit.x.shape[1]):
        return None
    # The errors-in-variables term is per row of the unit-norm column: the fewer rows' norm is smaller.
    eiv = fit.eiv * (np.sum(fit.x**2, axis=0) / np.maximum(np.sum(fit.x[keep] ** 2, axis=0), 1e-300))
    clear = replace(
        fit,
        starts=fit.starts[keep],
        ends=fit.ends[keep],
        x=fit.x[keep],
        y=fit.y[keep],
        eiv=eiv,
        groups=fit.groups[keep],
    )
    found = refit(clear, clear.x)
    return None if found is None else replace(clear, theta=found[0], j_std=float(found[1][0]))
