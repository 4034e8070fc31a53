"""Second stage of the fit: the log in SI units with what the windows and the regression need.

Speed noise, the zero-speed band, the kinks (torque steps and host stalls, which no interpolant places between slow
samples) and the integrals of the piecewise-cubic interpolant over the uneven sample times: the trapezoid rule
would miss the curvature between slow samples (a ringing loop) and bias J.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit.estimate import EstimatorSettings, Partial

RPM_TO_RAD_S = math.pi / 30.0
GAP_INTERVALS = 6.0  # no window spans more median intervals (a stall: a cubic misses a ringing loop's swing) ...
# ... nor a gap this long; a shorter one is never a stall: on a fast line (the simulator's unemulated one answers in
# 0.25 ms) six intervals are 1.5 ms, and a loaded host's usual few-ms hiccups cut every window there (2 of 4 runs with
# two CPU burners refused "too little acceleration", 1.6x and 7.7x the speed noise, on a load that passes idle); the
# loop's swing is resolved by the cubic across a gap this long, as at 115200 baud's own six intervals.
GAP_FLOOR_S = 0.01


@dataclass(frozen=True)
class Signals:
    """The log in SI units, with what the windows and integrals need."""

    t: np.ndarray
    rpm: np.ndarray
    w: np.ndarray
    pct: np.ndarray  # the torque reading, % of rated
    torque: np.ndarray  # N*m
    torque_step_pct: float  # the torque reading's resolution, % of rated (0: finer than the log shows, or unknown)
    torque_noise_pct: float  # the torque reading's error per sample (1 sigma, % of rated), its steps' rounding included
    noise_w: float
    band: float
    kink: np.ndarray
    cum_t: np.ndarray
    cum_w: np.ndarray
    moves: np.ndarray
    position: np.ndarray  # rad: cum_w, set after each stall by the drive's own position readings where the log has them


def signals(
    t: np.ndarray,
    rpm: np.ndarray,
    pct: np.ndarray,
    rated_torque_nm: float,
    cfg: EstimatorSettings,
    r: Partial,
    position_rad: np.ndarray | None = None,
) -> Signals:
    """Noise, zero-speed band, the torque reading's step, kinks (torque steps) and the Hermite integrals of torque
    and speed; the position over the log (position_rad: the drive's readings, NaN where none was read)."""
    speed_step = cfg.speed_step_rpm if cfg.speed_step_rpm is not None else reading_step(rpm)
    noise_rpm = cfg.speed_noise_rpm if cfg.speed_noise_rpm is not None else speed_noise_rpm(t, rpm, speed_step)
    r.speed_noise_rpm = noise_rpm
    peak = float(np.max(np.abs(rpm)))
    band = cfg.zero_band_rpm if cfg.zero_band_rpm is not None else max(0.02 * peak, 3.0 * noise_rpm)
    w = rpm * RPM_TO_RAD_S
    torque = pct / 100.0 * rated_torque_nm
    kink = kink_mask(t, rpm, pct, noise_rpm, cfg.kink_sigma, cfg.torque_noise_floor_pct)
    r.n_kinks = int(np.count_nonzero(kink))
    cum_w = cumulative_hermite(t, w, kink)
    torque_step_pct = cfg.torque_step_pct if cfg.torque_step_pct is not None else reading_step(pct)
    measured = cfg.torque_noise_pct if cfg.torque_noise_pct is not None else torque_noise_pct(t, pct)
    return Signals(
        t=t,
        rpm=rpm,
        w=w,
        pct=pct,
        torque=torque,
        torque_step_pct=torque_step_pct,
        torque_noise_pct=math.hypot(measured, torque_step_pct / math.sqrt(12.0)),
        noise_w=noise_rpm * RPM_TO_RAD_S,
        band=band,
        kink=kink,
        cum_t=cumulative_hermite(t, torque, kink),
        cum_w=cum_w,
        moves=move_ids(rpm, band),
        position=anchored(t, cum_w, position_rad),
    )


def gap_after(t: np.ndarray) -> np.ndarray:
    """For each sampling interval, whether it is a gap no window spans (a host stall): longer than GAP_INTERVALS
    median intervals and than GAP_FLOOR_S."""
    gaps = np.diff(t)
    return gaps > max(GAP_INTERVALS * float(np.median(gaps)), GAP_FLOOR_S) if gaps.size else np.zeros(0, dtype=bool)


def anchored(t: np.ndarray, cum_w: np.ndarray, position_rad: np.ndarray | None) -> np.ndarray:
    """The position at each sample: the integral of the speed, its offset set anew after every gap (gap_after: a
    host stall, the speed is not known across it, and a move may run through it)
    from the drive's position readings inside each stretch between gaps; a stretch with none keeps the offset of
    the one before it (of the first that has one, at the start)."""
    if position_rad is None or t.size < 2 or not np.any(np.isfinite(position_rad)):
        return cum_w
    stretch = np.zeros(t.size, dtype=int)
    stretch[1:] = np.cumsum(gap_after(t))
    read = np.isfinite(position_rad)
    offsets = np.full(int(stretch[-1]) + 1, np.nan)
    for k in range(offsets.size):
        here = read & (stretch == k)
        if np.any(here):
            offsets[k] = float(np.median(position_rad[here] - cum_w[here]))
    known = np.flatnonzero(np.isfinite(offsets))
    filled = offsets[known[np.clip(np.searchsorted(known, np.arange(offsets.size), side="right") - 1, 0, None)]]
    return cum_w + filled[stretch]


def line_deviation(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far each interior sample sits off the line through its two neighbours, and that deviation's standard
    deviation per unit of white measurement noise (sqrt(1 + a^2 + b^2), a + b = 1)."""
    if v.size < 3:
        return np.zeros(0), np.ones(0)
    t0, t1, t2 = t[:-2], t[1:-1], t[2:]
    a = (t2 - t1) / (t2 - t0)
    b = 1.0 - a
    return v[1:-1] - (a * v[:-2] + b * v[2:]), np.sqrt(1.0 + a**2 + b**2)


def speed_noise_rpm(t: np.ndarray, rpm: np.ndarray, step_rpm: float = 0.0) -> float:
    """Robust speed-noise estimate (floored at 0.1 rpm and at the rounding of a reading in steps of step_rpm): the
    smaller of the median deviations from the line through each sample's two neighbours and from the cubic through
    its four.

    Motion adds to both deviations, so each overestimates the noise: the line where the speed curves between
    samples (a ringing loop), the cubic where its wider stencil spans a corner of a short ramp. The median ignores
    the few samples that disagree with both. A reading in steps errs by up to half a step, uniformly over a speed
    that moves through them (step / sqrt 12 r.m.s.), yet a speed that moves through them slower than a step per
    sample reads on the line through its neighbours most of the time: the median misses that error, which is as
    much noise in each window's speed change as any (1 rpm at 50 rpm peaks: J 6 % low and a spring blamed).
    """
    estimates = [
        float(1.4826 * np.median(np.abs(dev) / ref))
        for dev, ref in (line_deviation(t, rpm), cubic_deviation(t, rpm))
        if dev.size
    ]
    return max(min(estimates, default=0.1), 0.1, step_rpm / math.sqrt(12.0))


def cubic_deviation(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Like line_deviation, against the cubic through the two samples on each side (Lagrange weights)."""
    if v.size < 5:
        return np.zeros(0), np.ones(0)
    c = np.arange(2, v.size - 2)
    offsets = (-2, -1, 1, 2)
    x = [t[c + j] - t[c] for j in offsets]
    weights = []
    for a, xa in enumerate(x):
        w = np.ones(c.size)
        for b, xb in enumerate(x):
            if a != b:
                w *= -xb / (xa - xb)
        weights.append(w)
    pred = sum(w * v[c + j] for w, j in zip(weights, offsets, strict=True))
    return v[c] - pred, np.sqrt(1.0 + sum(w**2 for w in weights))


def kink_mask(
    t: np.ndarray,
    rpm: np.ndarray,
    pct: np.ndarray,
    noise_rpm: float,
    kink_sigma: float,
    torque_noise_floor_pct: float,
) -> np.ndarray:
    """Samples at a torque step (torque or speed further than kink_sigma noise sigmas off the line through its
    neighbours; the torque noise estimated robustly, floored) or ending a gap (gap_after: a host stall)."""
    dev, ref = line_deviation(t, pct)
    torque_noise = max(torque_noise_pct(t, pct), torque_noise_floor_pct)
    dev_w, ref_w = line_deviation(t, rpm)
    kink = np.zeros(pct.size, dtype=bool)
    kink[1:-1] = (np.abs(dev) > kink_sigma * torque_noise * ref) | (np.abs(dev_w) > kink_sigma * noise_rpm * ref_w)
    kink[1:] |= gap_after(t)
    return kink


def torque_noise_pct(t: np.ndarray, pct: np.ndarray) -> float:
    """Robust torque-noise estimate from the log (% of rated): the median deviation from the line through each
    sample's neighbours. At a slow line the loop's swing between samples counts as noise too (an overestimate);
    the rest check measures the reading without motion (tuning.preflight)."""
    dev, ref = line_deviation(t, pct)
    return float(1.4826 * np.median(np.abs(dev) / ref)) if dev.size else 0.0


def move_ids(rpm: np.ndarray, band: float) -> np.ndarray:
    """Number of each sample's move: a new move starts wherever the speed enters, leaves or crosses the zero band."""
    sign = np.where(rpm >= band, 1, np.where(rpm <= -band, -1, 0))
    ids = np.zeros(rpm.size, dtype=int)
    ids[1:] = np.cumsum(sign[1:] != sign[:-1])
    return ids


def cumulative_hermite(t: np.ndarray, v: np.ndarray, kink: np.ndarray) -> np.ndarray:
    """Cumulative integral of the piecewise-cubic Hermite interpolant (the trapezoid rule plus its end corrections
    h^2/12 * (v'_i - v'_i+1)), with v' from three-point differences that never reach across a kink.

    The trapezoid rule alone is biased wherever the signal curves between samples: the plain trapezoid shrinks the
    integral of an oscillation by (x cot x) with x half its phase advance per sample, and the loop's response to
    a ramp corner (ringing of a loop tuned for the wrong inertia) is such an oscillation, which biases J low at slow
    sampling. Intervals touching a kink sample come out wrong but are never inside a window.
    """
    n = v.size
    out = np.zeros_like(v)
    if n < 2:
        return out
    h = np.diff(t)
    d = np.zeros_like(v)
    have = np.zeros(n, dtype=bool)
    if n >= 3:
        smooth3 = ~(kink[:-2] | kink[1:-1] | kink[2:])  # stencil samples s, s+1, s+2 all smooth
        h0, h1 = h[:-1], h[1:]
        v0, v1, v2 = v[:-2], v[1:-1], v[2:]
        central = (h0**2 * (v2 - v1) + h1**2 * (v1 - v0)) / (h0 * h1 * (h0 + h1))
        forward = -(2 * h0 + h1) / (h0 * (h0 + h1)) * v0 + (h0 + h1) / (h0 * h1) * v1 - h0 / (h1 * (h0 + h1)) * v2
        backward = h1 / (h0 * (h0 + h1)) * v0 - (h0 + h1) / (h0 * h1) * v1 + (2 * h1 + h0) / (h1 * (h0 + h1)) * v2
        # later assignments win: central where its stencil is smooth, else one-sided into smooth data
        for idx, vals in ((np.arange(2, n), backward), (np.arange(0, n - 2), forward), (np.arange(1, n - 1), central)):
            d[idx[smooth3]] = vals[smooth3]
            have[idx[smooth3]] = True
    secant = np.diff(v) / h
    # fall back to the secant of an interval with no kink at its other end (first order, at few samples only)
    for idx, other, vals in (
        (np.arange(0, n - 1), np.arange(1, n), secant),
        (np.arange(1, n), np.arange(0, n - 1), secant),
    ):
        fill = ~have[idx] & ~kink[other]
        d[idx[fill]] = vals[fill]
        have[idx[fill]] = True
    out[1:] = np.cumsum(0.5 * h * (v[1:] + v[:-1]) + h * h / 12.0 * (d[:-1] - d[1:]))
    return out


def reading_step(values: np.ndarray) -> float:
    """The step of a reading where every value lies on one grid (a torque read in whole percent), else 0."""
    values = np.unique(values)
    if values.size < 3:
        return 0.0
    step = float(np.min(np.diff(values)))
    grid = (values - values[0]) / step
    return step if float(np.max(np.abs(grid - np.round(grid)))) < 0.01 else 0.0


# A stall named as such (fit.gaps, the refusals): a gap between samples while the axis moved ...
STALL_S = 0.05  # a gap this long ...
STALL_INTERVALS = 6.0  # ... and this many usual intervals is a stall (the windows never span one: gap_after)
MOVING_SHARE = 0.05  # ... where the speed on either side is above this share of the peak


def stall(t: np.ndarray, rpm: np.ndarray) -> tuple[float, float]:
    """(the longest gap between two samples while the axis moved, the median interval) in s; (0, median) where
    no gap is a stall."""
    if t.size < 3:
        return 0.0, 0.0
    gaps = np.diff(t)
    usual = float(np.median(gaps))
    speed = np.abs(rpm)
    moving = np.maximum(speed[1:], speed[:-1]) > MOVING_SHARE * float(np.max(speed))
    long = moving & (gaps >= max(STALL_S, STALL_INTERVALS * usual))
    return (float(np.max(gaps[long])) if np.any(long) else 0.0), usual


def stall_words(t: np.ndarray, rpm: np.ndarray) -> str:
    """The words for the log's longest stall while the axis moved; empty where it has none."""
    gap, usual = stall(t, rpm)
    if gap <= 0:
        return ""
    return (
        f"sampling gaps of up to {1000 * gap:.0f} ms while the axis moved (usually {1000 * usual:.2g} ms: the host "
        "stalled, a busy machine?)"
    )
