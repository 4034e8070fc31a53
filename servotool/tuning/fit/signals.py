"""Second stage of the fit: the log in SI units with what the windows and the regression need.

Speed noise, the zero-speed band, the kinks (torque steps and host stalls, which no interpolant places between slow
samples), the speed's corners (the intervals a torque step fell in) and the integrals of the piecewise-cubic
interpolant over the uneven sample times: the trapezoid rule would miss the curvature between slow samples (a
ringing loop) and bias J.

At a slow line (CORNERS_BETWEEN_S) nothing that picks the windows looks at a speed sample's own deviation: a window
end kept because its noise hid a corner carries that noise's sign into the window's speed change (J came out
0.5-1 % high at 24 samples/s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
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
# An interval this many median intervals long (and GAP_FLOOR_S) lost a sample the host was late for, or held a
# stall: the moves' commands were late inside it too, so a torque step may lie anywhere in it, too small against
# the noise to show as a corner (corner_cuts); no window spans it (DSX7E 19200 with 60-120 ms stalls: J 4 sigma
# low). A position read lengthens an interval to under 2 (SDC 9600: 1.6, DSX7E 19200: 1.9).
LATE_INTERVALS = 2.5
# Sampled this slowly (median interval, s), a move's ramp is a few samples and a torque step's corner falls between
# two of them, the loop's response to it shorter than an interval: the corners are cut where they lie (corner_cuts)
# and the noise read away from them (speed_noise_rpm with kink), so that no window end is picked by its own noise
# (SDC 9600, 24 samples/s: J was 0.5-1 % high, +1.0 sigma). Faster, the turn through a corner spans samples, as a
# backlash crossing does, and the samples off the line are left out with the intervals beside them (off_line):
# the cut alone left J 8 % low on DSX7E 19200 with 30 % Coulomb, and hid DSX7E 115200's backlash.
CORNERS_BETWEEN_S = 0.03
MIN_NOISE_SAMPLES = 10  # fewer clear samples than this: the speed noise is estimated from every sample
MOVING_NOISE_SHARE = 0.02  # the noise is estimated where the stencil moves faster than this share of the peak ...
NOISE_PASSES = 2  # ... and away from the corners found with the estimate before (each pass a lower threshold)
# A corner this many times its own threshold also cuts the intervals beside it: a loop's response to a torque step
# lasts past the sample after it (a few % of the corner, as much as the noise once the corner is this large).
SPILL_FACTOR = 12.0
# The torque leaving its own side's line this many noise sigmas at a corner's sample also cuts the interval beyond
# it: a speed loop's response turns the torque smoothly through the corner (DSX7E 19200, Coulomb 30 %: J 8 % low).
BENT_SIGMA = 2.0


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
    cut: np.ndarray  # per sampling interval: a speed corner lies in it (corner_cuts); no window or slope spans it
    cum_t: np.ndarray
    cum_w: np.ndarray
    moves: np.ndarray
    position: np.ndarray  # rad: cum_w, set after each stall by the drive's own position readings where the log has them
    own: np.ndarray  # per sampling interval: the time (s) the sampler paused in it by its own choice (paused_within)


def signals(
    t: np.ndarray,
    rpm: np.ndarray,
    pct: np.ndarray,
    rated_torque_nm: float,
    cfg: EstimatorSettings,
    r: Partial,
    position_rad: np.ndarray | None = None,
    paused: Sequence[tuple[float, float]] = (),
) -> Signals:
    """Noise, zero-speed band, the torque reading's step, kinks (torque steps), the speed's corners and the Hermite
    integrals of torque and speed; the position over the log (position_rad: the drive's readings, NaN where none
    was read); the sampler's own pauses (paused: from, to) per interval."""
    speed_step = cfg.speed_step_rpm if cfg.speed_step_rpm is not None else reading_step(rpm)
    kink = kink_mask(t, pct, cfg.kink_sigma, cfg.torque_noise_floor_pct)
    between = not cfg.speed_between_reads and t.size > 1 and float(np.median(np.diff(t))) >= CORNERS_BETWEEN_S
    if cfg.speed_noise_rpm is not None:
        noise_rpm = cfg.speed_noise_rpm
    elif between:
        noise_rpm = speed_noise_rpm(t, rpm, speed_step, kink=kink, pct=pct, corner_sigma=cfg.kink_sigma)
    else:
        noise_rpm = speed_noise_rpm(t, rpm, speed_step)
    r.speed_noise_rpm = noise_rpm
    peak = float(np.max(np.abs(rpm)))
    band = cfg.zero_band_rpm if cfg.zero_band_rpm is not None else max(0.02 * peak, 3.0 * noise_rpm)
    w = rpm * RPM_TO_RAD_S
    torque = pct / 100.0 * rated_torque_nm
    if between:
        cut = corner_cuts(t, rpm, cfg.kink_sigma * noise_rpm)
        torque_noise = max(torque_noise_pct(t, pct), cfg.torque_noise_floor_pct)
        cut = cut | bent_beside(t, pct, cut, BENT_SIGMA * torque_noise) | late_intervals(t)
    else:
        kink = kink | off_line(t, rpm, cfg.kink_sigma * noise_rpm)
        cut = np.zeros(max(t.size - 1, 0), dtype=bool)
    r.n_kinks = int(np.count_nonzero(kink)) + int(np.count_nonzero(cut))
    cum_w = cumulative_hermite(t, w, kink, cut)
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
        cut=cut,
        cum_t=cumulative_hermite(t, torque, kink, cut),
        cum_w=cum_w,
        moves=move_ids(rpm, band),
        position=anchored(t, cum_w, position_rad),
        own=paused_within(t, paused),
    )


def gap_after(t: np.ndarray) -> np.ndarray:
    """For each sampling interval, whether it is a gap no window spans (a host stall): longer than GAP_INTERVALS
    median intervals and than GAP_FLOOR_S."""
    return longer_than(t, GAP_INTERVALS)


def late_intervals(t: np.ndarray) -> np.ndarray:
    """For each sampling interval, whether it is longer than LATE_INTERVALS median intervals and GAP_FLOOR_S."""
    return longer_than(t, LATE_INTERVALS)


def longer_than(t: np.ndarray, intervals: float) -> np.ndarray:
    """For each sampling interval, whether it is longer than `intervals` median intervals and than GAP_FLOOR_S."""
    gaps = np.diff(t)
    return gaps > max(intervals * float(np.median(gaps)), GAP_FLOOR_S) if gaps.size else np.zeros(0, dtype=bool)


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


def speed_noise_rpm(
    t: np.ndarray,
    rpm: np.ndarray,
    step_rpm: float = 0.0,
    *,
    kink: np.ndarray | None = None,
    pct: np.ndarray | None = None,
    corner_sigma: float = 5.0,
) -> float:
    """Robust speed-noise estimate (floored at 0.1 rpm and at the rounding of a reading in steps of step_rpm): the
    smallest of the median deviations from the line through each sample's two neighbours, from the cubic through
    its four, and (pct: the torque log) from that line once the curvature the torque's slope explains is taken out.

    Motion adds to every deviation, so each overestimates the noise: the line where the speed curves between
    samples (a ringing loop: the torque's slope explains it), the cubic where its wider stencil spans a corner of a
    short ramp. With kink (the torque steps) given, only stencils clear of them, moving (MOVING_NOISE_SHARE) and
    clear of the speed corners the estimate before found (corner_sigma of it off the line, NOISE_PASSES) count: at
    24 samples/s a move is a few samples, and its corners took a third of them (the median read 15-100 % high, which
    over-corrected J by errors-in-variables). A reading in steps errs by up to half a step, uniformly over a speed
    that moves through them (step / sqrt 12 r.m.s.), yet a speed that moves through them slower than a step per
    sample reads on the line through its neighbours most of the time: the median misses that error, which is as
    much noise in each window's speed change as any (1 rpm at 50 rpm peaks: J 6 % low and a spring blamed).
    """
    if kink is None:
        estimate = clear_noise(t, rpm, None, None)
    else:
        speed = np.abs(rpm)
        moving = speed > MOVING_NOISE_SHARE * float(np.max(speed, initial=0.0))
        estimate = clear_noise(t, rpm, kink, moving, pct)
        for _ in range(NOISE_PASSES):
            dev, ref = line_deviation(t, rpm)
            corners = kink.copy()
            corners[1:-1] |= np.abs(dev) > corner_sigma * max(estimate, 0.1) * ref
            estimate = clear_noise(t, rpm, corners, moving, pct)
    return max(estimate, 0.1, step_rpm / math.sqrt(12.0))


def clear_noise(
    t: np.ndarray,
    rpm: np.ndarray,
    excluded: np.ndarray | None,
    moving: np.ndarray | None,
    pct: np.ndarray | None = None,
) -> float:
    """speed_noise_rpm's estimate over the stencils that hold no excluded sample and only moving ones (None: all);
    over every stencil where fewer than MIN_NOISE_SAMPLES are."""
    estimates = []
    for half, (dev, ref) in ((1, line_deviation(t, rpm)), (2, cubic_deviation(t, rpm))):
        if not dev.size:
            continue
        clear = np.ones(dev.size, dtype=bool)
        if excluded is not None and moving is not None:
            span = np.ones(2 * half + 1)
            near = np.convolve(excluded | ~moving, span, mode="valid")
            clear = near == 0
            if np.count_nonzero(clear) < MIN_NOISE_SAMPLES:
                clear[:] = True
        estimates.append(float(1.4826 * np.median(np.abs(dev[clear]) / ref[clear])))
        if half == 1 and pct is not None:
            estimates.append(torque_explained_noise(t, pct, dev[clear], ref[clear], clear))
    return min(estimates, default=0.1)


def torque_explained_noise(t: np.ndarray, pct: np.ndarray, dev: np.ndarray, ref: np.ndarray, at: np.ndarray) -> float:
    """The line deviations' median once the part the torque's slope explains is taken out: a rigid load's speed
    curves by the torque's slope over J, off the line by h0*h1/2 times that (one coefficient fitted for all, so no
    J is needed). dev, ref: the line deviations at the interior samples `at` selects."""
    h0, h1 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
    slope = (pct[2:] - pct[:-2]) / (t[2:] - t[:-2])
    curve = (-0.5 * h0 * h1 * slope)[at]
    norm = float(curve @ curve)
    if norm <= 0:
        return math.inf
    return float(1.4826 * np.median(np.abs(dev - float(curve @ dev) / norm * curve) / ref))


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


def kink_mask(t: np.ndarray, pct: np.ndarray, kink_sigma: float, torque_noise_floor_pct: float) -> np.ndarray:
    """Samples at a torque step (torque further than kink_sigma noise sigmas off the line through its neighbours;
    the torque noise estimated robustly, floored) or ending a gap (gap_after: a host stall). The torque's noise is
    not the speed's: a kink found here selects no window end on its speed noise (corner_cuts finds the rest)."""
    kink = off_line(t, pct, kink_sigma * max(torque_noise_pct(t, pct), torque_noise_floor_pct))
    kink[1:] |= gap_after(t)
    return kink


def off_line(t: np.ndarray, v: np.ndarray, limit: float) -> np.ndarray:
    """Samples further than limit (times their noise factor) off the line through their neighbours: a torque step
    (kink_mask), or a speed kink judged on the sample's own noise (a fast log's, or speed read apart:
    CORNERS_BETWEEN_S)."""
    dev, ref = line_deviation(t, v)
    out = np.zeros(v.size, dtype=bool)
    out[1:-1] = np.abs(dev) > limit * ref
    return out


def corner_cuts(t: np.ndarray, rpm: np.ndarray, limit_rpm: float) -> np.ndarray:
    """Per sampling interval, whether a speed corner (a torque step the torque's noise hid) lies in it: where the
    change of slope from the interval before it to the interval after it is the largest of its neighbourhood and
    further than limit_rpm-sigma noise would move it (limit_rpm: the noise times the sigmas); a corner SPILL_FACTOR
    times that also cuts the intervals beside it.

    A corner between two samples splits its deviation from the lines through their neighbours between them by
    where it fell, so a test of each sample alone finds it at one sample and misses it at the other when its
    share is near the limit, keeping the samples whose noise hid it; the change of slope across the interval is
    the whole corner wherever it fell, and only a fraction of it across the intervals beside it, however uneven
    the sampling (a position read lengthens the interval it falls in). Only the interval is cut: its two samples
    still end the windows on either side, the corner being between them.
    """
    cut = np.zeros(max(rpm.size - 1, 0), dtype=bool)
    if rpm.size < 4:
        return cut
    h = np.diff(t)
    slope = np.diff(rpm) / h
    jump = np.abs(slope[2:] - slope[:-2])  # across interval i = 1..n-3
    noise = np.sqrt(2.0 / h[:-2] ** 2 + 2.0 / h[2:] ** 2)
    before = np.concatenate(([0.0], jump[:-1]))
    after = np.concatenate((jump[1:], [0.0]))
    corner = (jump > limit_rpm * noise) & (jump >= before) & (jump >= after)
    spill = corner & (jump > SPILL_FACTOR * limit_rpm * noise)
    cut[1:-1] = corner
    cut[:-2] |= spill
    cut[2:] |= spill
    return cut


def bent_beside(t: np.ndarray, pct: np.ndarray, cut: np.ndarray, limit_pct: float) -> np.ndarray:
    """The intervals beside each cut one (cut: per interval) whose sample next to the cut has its torque further
    than limit_pct (times its noise factor) off the line through the two samples beyond it on its own side: the
    torque still turned there, so the window ending at that sample would integrate the turn with a one-sided slope.
    A torque step inside the cut interval leaves both sides' lines straight; the speed's noise is not looked at."""
    out = np.zeros_like(cut)
    if t.size < 4:
        return out
    before = _off_extrapolated(t, pct, limit_pct)  # sample i off the line through i-2, i-1
    after = _off_extrapolated(-t[::-1], pct[::-1], limit_pct)[::-1]  # ... through i+1, i+2: the same, time reversed
    out[:-1] |= cut[1:] & before[1:-1]  # interval (i-1, i) before a cut (i, i+1), torque bent at i
    out[1:] |= cut[:-1] & after[1:-1]  # interval (i+1, i+2) after a cut (i, i+1), torque bent at i+1
    return out


def _off_extrapolated(t: np.ndarray, v: np.ndarray, limit: float) -> np.ndarray:
    """Samples further than limit (times their noise factor) off the line through the two samples before them."""
    h = np.diff(t)
    ratio = h[1:] / h[:-1]
    off = v[2:] - (v[1:-1] + (v[1:-1] - v[:-2]) * ratio)
    out = np.zeros(v.size, dtype=bool)
    out[2:] = np.abs(off) > limit * np.sqrt(1.0 + (1.0 + ratio) ** 2 + ratio**2)
    return out


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


def cumulative_hermite(t: np.ndarray, v: np.ndarray, kink: np.ndarray, cut: np.ndarray | None = None) -> np.ndarray:
    """Cumulative integral of the piecewise-cubic Hermite interpolant (the trapezoid rule plus its end corrections
    h^2/12 * (v'_i - v'_i+1)), with v' from three-point differences that never reach across a kink or a cut
    interval (cut: per interval, a corner lies in it; None: none).

    The trapezoid rule alone is biased wherever the signal curves between samples: the plain trapezoid shrinks the
    integral of an oscillation by (x cot x) with x half its phase advance per sample, and the loop's response to
    a ramp corner (ringing of a loop tuned for the wrong inertia) is such an oscillation, which biases J low at slow
    sampling. Intervals touching a kink sample, and cut ones, come out wrong but are never inside a window.
    """
    n = v.size
    out = np.zeros_like(v)
    if n < 2:
        return out
    if cut is None:
        cut = np.zeros(n - 1, dtype=bool)
    h = np.diff(t)
    d = np.zeros_like(v)
    have = np.zeros(n, dtype=bool)
    if n >= 3:
        smooth3 = ~(kink[:-2] | kink[1:-1] | kink[2:] | cut[:-1] | cut[1:])  # samples s..s+2 smooth, no corner
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
        fill = ~have[idx] & ~kink[other] & ~cut
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


def paused_within(t: np.ndarray, paused: Sequence[tuple[float, float]]) -> np.ndarray:
    """Per interval between the samples at times `t`: how much of it (s) lies in the sampler's own pauses
    (from, to), on t's clock."""
    t = np.asarray(t, dtype=float)
    own = np.zeros(max(0, t.size - 1))
    for began, ended in paused:
        own += np.clip(np.minimum(ended, t[1:]) - np.maximum(began, t[:-1]), 0.0, None)
    return own


def host_gaps(t: np.ndarray, own: np.ndarray | None = None) -> np.ndarray:
    """The time between each two samples that the host took (s): the gap less the sampler's own pause in it (own, per
    interval: paused_within), so that a fit between moves is no stall of the host's."""
    gaps = np.diff(t)
    return gaps - own if own is not None else gaps


def stall(t: np.ndarray, rpm: np.ndarray, own: np.ndarray | None = None) -> tuple[float, float]:
    """(the longest gap between two samples while the axis moved, the median interval) in s; (0, median) where
    no gap is a stall. own: per interval, the time the sampler paused by its own choice (paused_within: a fit between
    moves while the drive held): the host's stall is the rest of the gap. A ringing load still moves in such a pause,
    and blaming the host for it named a stall on an idle machine (DSX7E, two-mass 20 Hz: 100 ms fits)."""
    if t.size < 3:
        return 0.0, 0.0
    usual = float(np.median(np.diff(t)))
    gaps = host_gaps(t, own)
    speed = np.abs(rpm)
    moving = np.maximum(speed[1:], speed[:-1]) > MOVING_SHARE * float(np.max(speed))
    long = moving & (gaps >= max(STALL_S, STALL_INTERVALS * usual))
    return (float(np.max(gaps[long])) if np.any(long) else 0.0), usual


def stall_words(t: np.ndarray, rpm: np.ndarray, own: np.ndarray | None = None) -> str:
    """The words for the log's longest stall while the axis moved (own: as stall's); empty where it has none."""
    gap, usual = stall(t, rpm, own)
    if gap <= 0:
        return ""
    return (
        f"sampling gaps of up to {1000 * gap:.0f} ms while the axis moved (usually {1000 * usual:.2g} ms: the host "
        "stalled, a busy machine?)"
    )
