"""A measured score of a machine's response, and the verdict between two scores: pure.

One run is a standard test motion's legs (a speed step at the shortest ramp, then a trapezoidal move back); each
figure carries how coarse the line's sampling makes it (its resolution), and repeats give its spread. Two scores
differ only where the difference exceeds both twice their combined spread and the coarser resolution: what the
measurement cannot tell apart is called unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit.spectrum import spectrum

SETTLE_BAND = 0.05  # settled within 5 % of the target (a 2 % band sits inside typical speed-reading noise)
SPREAD_SIGMAS = 2.0  # a difference counts beyond this many of the two scores' combined standard deviations ...
PRINTED_SHARE = 0.02  # ... and beyond this share of the larger figure (what repeats at zero noise cannot show)

# name: (unit, judged: part of the overall verdict, lower is better)
FIGURES: dict[str, tuple[str, bool]] = {
    "overshoot": ("%", True),
    "settling": ("ms", True),
    "following_error_rms": ("rev", True),
    "following_error_peak": ("rev", True),
    "iae": ("rev", True),
    "ripple": ("rpm", True),
    "torque_rms": ("%", False),
    "ringing": ("Hz", False),
}


@dataclass(frozen=True)
class LegSamples:
    """One leg: direction, its ramp (ms from 0 to rated speed), samples from its command (s, rpm, % of rated)."""

    direction: int
    ramp_ms: float
    t: Sequence[float]
    speed_rpm: Sequence[float]
    torque_pct: Sequence[float]
    command_ms: float


@dataclass(frozen=True)
class Figure:
    """One figure of a run or a score: its value (None: not found, e.g. no ringing, never settled), its spread
    over repeats (standard deviation; 0 for one run) and how coarse the sampling makes it."""

    value: float | None
    spread: float
    resolution: float


@dataclass(frozen=True)
class Score:
    figures: dict[str, Figure]
    runs: int
    rate_hz: float  # samples per second
    nyquist_hz: float


def reference(leg: LegSamples, speed_rpm: float, rated_rpm: float) -> np.ndarray:
    """The speed the drive's JOG ramp commands at each sample: from the middle of the command's transmission,
    up at the leg's ramp to speed_rpm."""
    t = np.asarray(leg.t, dtype=float)
    slope = rated_rpm / max(leg.ramp_ms / 1000.0, 1e-6)
    started = np.clip(t - leg.command_ms / 2000.0, 0.0, None)
    ref = np.minimum(speed_rpm, slope * started) * leg.direction
    ref[0] = 0.0
    return ref


def score_run(legs: Sequence[LegSamples], speed_rpm: float, rated_rpm: float, lsb: Mapping[str, float]) -> Score:
    """The figures of one run. The first leg is the speed step (overshoot, settling, ripple, ringing are its);
    following error and IAE cover every leg. lsb: the readings' steps ('speed' rpm, 'torque' %)."""
    step = legs[0]
    t, v = np.asarray(step.t, dtype=float), np.asarray(step.speed_rpm, dtype=float) * step.direction
    gaps = np.diff(t[1:]) if t.size > 2 else np.array([0.0])
    interval = float(np.median(gaps)) if gaps.size else 0.0
    figures: dict[str, Figure] = {}
    peak = int(np.argmax(v))
    jump = float(np.max(np.abs(np.diff(v[max(0, peak - 1) : peak + 2])))) if v.size > 1 else 0.0
    figures["overshoot"] = Figure(
        max(0.0, (float(v[peak]) - speed_rpm) / speed_rpm * 100.0), 0.0, jump / 2.0 / speed_rpm * 100.0
    )
    outside = np.flatnonzero(np.abs(v - speed_rpm) > SETTLE_BAND * speed_rpm)
    settled = None if outside.size and outside[-1] == v.size - 1 else float(t[outside[-1] + 1] if outside.size else 0)
    figures["settling"] = Figure(None if settled is None else settled * 1000.0, 0.0, interval * 1000.0)
    late = v[t >= t[-1] / 2] if t.size else v
    figures["ripple"] = Figure(float(np.std(late)) if late.size > 2 else 0.0, 0.0, lsb.get("speed", 0.0))
    figures.update(_errors(legs, speed_rpm, rated_rpm))
    torque = np.concatenate([np.asarray(leg.torque_pct, dtype=float) for leg in legs])
    figures["torque_rms"] = Figure(
        float(np.sqrt(np.mean(torque**2))) if torque.size else None, 0.0, lsb.get("torque", 0.0)
    )
    figures["ringing"], nyquist = _ringing(step, speed_rpm, rated_rpm)
    return Score(figures, 1, 1.0 / interval if interval > 0 else 0.0, nyquist)


def _errors(legs: Sequence[LegSamples], speed_rpm: float, rated_rpm: float) -> dict[str, Figure]:
    """Following error (rev: the speed error integrated over each leg) and IAE (rev: its absolute value's
    integral). Their resolution: what the straight line between samples can miss (half each interval's change of
    the error times the interval) and the command's time on the line (the ramp starts somewhere inside it)."""
    follow: list[np.ndarray] = []
    iae = miss = timing = peak_miss = 0.0
    for leg in legs:
        t = np.asarray(leg.t, dtype=float)
        err = reference(leg, speed_rpm, rated_rpm) - np.asarray(leg.speed_rpm, dtype=float)
        dt = np.diff(t)
        pieces = 0.5 * (err[1:] + err[:-1]) * dt / 60.0
        follow.append(np.concatenate(([0.0], np.cumsum(pieces))))
        iae += float(np.sum(0.5 * (np.abs(err[1:]) + np.abs(err[:-1])) * dt)) / 60.0
        changes = np.abs(np.diff(err)) * dt / 2.0 / 60.0
        miss += abs(float(np.sum(np.diff(err) * dt))) / 2.0 / 60.0
        peak_miss = max(peak_miss, float(np.max(changes)) if changes.size else 0.0)
        timing = max(timing, speed_rpm / 60.0 * leg.command_ms / 2000.0)
    e = np.concatenate(follow)
    return {
        "following_error_rms": Figure(float(np.sqrt(np.mean(e**2))), 0.0, math.hypot(miss, timing)),
        "following_error_peak": Figure(float(np.max(np.abs(e))), 0.0, math.hypot(peak_miss, timing)),
        "iae": Figure(iae, 0.0, math.hypot(miss, timing)),
    }


def _ringing(step: LegSamples, speed_rpm: float, rated_rpm: float) -> tuple[Figure, float]:
    """The strongest resolvable peak of the speed error once the ramp is done (Hz; None: none), resolution one
    frequency bin; and the Nyquist limit."""
    t = np.asarray(step.t, dtype=float)
    ramp_s = step.ramp_ms / 1000.0 * speed_rpm / rated_rpm + step.command_ms / 1000.0
    keep = t > ramp_s
    found = spectrum(t[keep], np.asarray(step.speed_rpm, dtype=float)[keep]) if np.sum(keep) >= 8 else None
    if found is None:
        return Figure(None, 0.0, 0.0), 0.0
    resolved = [p for p in found.peaks if p.resolvable]
    return Figure(resolved[0].hz if resolved else None, 0.0, found.resolution_hz), found.nyquist_hz


def combine(runs: Sequence[Score]) -> Score:
    """The score of repeated runs: each figure's mean, its standard deviation (spread) and the coarsest resolution.
    A figure missing from any run (never settled, no ringing in one) is missing from the score where it is missing
    from most runs, else the mean of the runs that have it."""
    figures: dict[str, Figure] = {}
    for name in FIGURES:
        values = [r.figures[name].value for r in runs if name in r.figures]
        present = [v for v in values if v is not None]
        resolution = max((r.figures[name].resolution for r in runs if name in r.figures), default=0.0)
        if len(present) * 2 <= len(values) and (name != "ringing" or not present):
            figures[name] = Figure(None, 0.0, resolution)
            continue
        spread = float(np.std(present, ddof=1)) if len(present) > 1 else 0.0
        figures[name] = Figure(float(np.mean(present)), spread, resolution)
    rate = float(np.median([r.rate_hz for r in runs])) if runs else 0.0
    nyquist = float(np.median([r.nyquist_hz for r in runs])) if runs else 0.0
    return Score(figures, sum(r.runs for r in runs), rate, nyquist)


@dataclass(frozen=True)
class Difference:
    name: str
    before: Figure
    after: Figure
    margin: float  # what the difference must exceed to count
    verdict: str  # better | worse | unchanged | not comparable


def compare(before: Score, after: Score, judged: tuple[str, ...] | None = None) -> tuple[list[Difference], str]:
    """Each figure's difference with its verdict, and the overall verdict from the judged figures (default: those
    FIGURES marks; a function names the ones it is for): better where one improved beyond its margin and none got
    worse, worse where any got worse, else unchanged."""
    diffs: list[Difference] = []
    for name, (_unit, _judged) in FIGURES.items():
        a, b = before.figures.get(name), after.figures.get(name)
        if a is None or b is None:
            continue
        margin = max(
            SPREAD_SIGMAS * math.hypot(a.spread, b.spread),
            max(a.resolution, b.resolution),
            PRINTED_SHARE * max(abs(a.value or 0.0), abs(b.value or 0.0)),
        )
        diffs.append(Difference(name, a, b, margin, _verdict(name, a, b, margin)))
    names = judged if judged is not None else tuple(n for n, (_u, j) in FIGURES.items() if j)
    counted = [d for d in diffs if d.name in names]
    if any(d.verdict == "worse" for d in counted):
        overall = "worse"
    elif any(d.verdict == "better" for d in counted):
        overall = "better"
    else:
        overall = "unchanged"
    return diffs, overall


def _verdict(name: str, a: Figure, b: Figure, margin: float) -> str:
    if name == "ringing":  # a frequency: gone, appeared or moved; judged by the ripple it makes
        if a.value is None and b.value is None:
            return "unchanged"
        if a.value is None or b.value is None:
            return "better" if b.value is None else "worse"
        return "unchanged" if abs(b.value - a.value) <= margin else "moved"
    if a.value is None and b.value is None:
        return "unchanged"
    if a.value is None or b.value is None:  # settling: never settled before, or no longer
        return "better" if a.value is None else "worse"
    delta = b.value - a.value
    if abs(delta) <= margin:
        return "unchanged"
    return "better" if delta < 0 else "worse"
