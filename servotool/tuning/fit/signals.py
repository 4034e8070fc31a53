"""Numerical building blocks of the inertia fit (tuning.fit.estimate): speed-noise estimates from sample deviations,
windows of constant speed sign, least squares corrected for a noisy regressor, the jackknife, and integrals of
the piecewise-cubic interpolant over uneven sample times."""

from __future__ import annotations

import math

import numpy as np


def line_deviation(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far each interior sample sits off the line through its two neighbours, and that deviation's standard
    deviation per unit of white measurement noise (sqrt(1 + a^2 + b^2), a + b = 1)."""
    if v.size < 3:
        return np.zeros(0), np.ones(0)
    t0, t1, t2 = t[:-2], t[1:-1], t[2:]
    a = (t2 - t1) / (t2 - t0)
    b = 1.0 - a
    return v[1:-1] - (a * v[:-2] + b * v[2:]), np.sqrt(1.0 + a**2 + b**2)


def speed_noise_rpm(t: np.ndarray, rpm: np.ndarray) -> float:
    """Robust speed-noise estimate (floored at 0.1 rpm): the smaller of the median deviations from the line through
    each sample's two neighbours and from the cubic through its four.

    Motion adds to both deviations, so each overestimates the noise: the line where the speed curves between
    samples (a ringing loop at 20-40 samples/s tripled the estimate), the cubic where its wider stencil spans a
    corner of a short ramp. The median ignores the few samples that disagree with both.
    """
    estimates = [
        float(1.4826 * np.median(np.abs(dev) / ref))
        for dev, ref in (line_deviation(t, rpm), cubic_deviation(t, rpm))
        if dev.size
    ]
    return max(min(estimates, default=0.1), 0.1)


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
    gap_intervals: float,
) -> np.ndarray:
    """Samples at a torque step (torque or speed further than kink_sigma noise sigmas off the line through its
    neighbours; the torque noise estimated robustly, floored) or ending a gap of more than gap_intervals median
    sampling intervals (a host stall)."""
    dev, ref = line_deviation(t, pct)
    torque_noise = max(float(1.4826 * np.median(np.abs(dev) / ref)), torque_noise_floor_pct) if dev.size else 0.0
    dev_w, ref_w = line_deviation(t, rpm)
    kink = np.zeros(pct.size, dtype=bool)
    kink[1:-1] = (np.abs(dev) > kink_sigma * torque_noise * ref) | (np.abs(dev_w) > kink_sigma * noise_rpm * ref_w)
    gaps = np.diff(t)
    kink[1:] |= gaps > gap_intervals * float(np.median(gaps))
    return kink


def sign_windows(rpm: np.ndarray, band: float, kink: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint windows of k sampling intervals whose samples all lie outside the zero band with one sign.

    A torque kink sample gets sign 0 too, which cuts the intervals on both sides of it out of every window.
    """
    sign = np.where(rpm >= band, 1, np.where(rpm <= -band, -1, 0))
    sign[kink] = 0
    starts: list[int] = []
    i, n = 0, rpm.size
    while i < n - 1:
        if sign[i] == 0:
            i += 1
            continue
        j = i
        while j + 1 < n and sign[j + 1] == sign[i]:
            j += 1
        # samples i..j form one run of constant sign
        for s in range(i, j - k + 1, k):
            starts.append(s)
        i = j + 1
    st = np.asarray(starts, dtype=int)
    return st, st + k


def move_ids(rpm: np.ndarray, band: float) -> np.ndarray:
    """Number of each sample's move: a new move starts wherever the speed enters, leaves or crosses the zero band."""
    sign = np.where(rpm >= band, 1, np.where(rpm <= -band, -1, 0))
    ids = np.zeros(rpm.size, dtype=int)
    ids[1:] = np.cumsum(sign[1:] != sign[:-1])
    return ids


def corrected_lstsq(xs: np.ndarray, y: np.ndarray, eiv: np.ndarray) -> np.ndarray:
    """Least squares with the expected regressor-noise variance per row (eiv) taken out of X'X."""
    return np.linalg.solve(xs.T @ xs - xs.shape[0] * np.diag(eiv), xs.T @ y)


def jackknife_std(xs: np.ndarray, y: np.ndarray, eiv: np.ndarray, groups: np.ndarray, min_groups: int) -> np.ndarray:
    """Delete-one-group jackknife standard deviation of the (column-scaled) least-squares parameters."""
    labels = np.unique(groups)
    g = labels.size
    if g < max(min_groups, 2):
        return np.zeros(xs.shape[1])
    thetas = []
    for label in labels:
        keep = groups != label
        if np.count_nonzero(keep) <= xs.shape[1]:
            return np.zeros(xs.shape[1])
        try:
            thetas.append(corrected_lstsq(xs[keep], y[keep], eiv))
        except np.linalg.LinAlgError:  # the rest cannot determine the parameters: no honest bound
            return np.full(xs.shape[1], np.inf)
    th = np.asarray(thetas)
    return np.sqrt((g - 1) / g * np.sum((th - th.mean(axis=0)) ** 2, axis=0))


def cumulative_hermite(t: np.ndarray, v: np.ndarray, kink: np.ndarray) -> np.ndarray:
    """Cumulative integral of the piecewise-cubic Hermite interpolant (the trapezoid rule plus its end corrections
    h^2/12 * (v'_i - v'_i+1)), with v' from three-point differences that never reach across a kink.

    The trapezoid rule alone is biased wherever the signal curves between samples: the plain trapezoid shrinks the
    integral of an oscillation by (x cot x) with x half its phase advance per sample, and the loop's response to
    a ramp corner (ringing of a loop tuned for the wrong inertia) is such an oscillation; at 20-40 samples/s that
    biased J low by 1-3 %. Intervals touching a kink sample come out wrong but are never inside a window.
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


def ma1_std(
    xs: np.ndarray, y: np.ndarray, eiv: np.ndarray, resid: np.ndarray, starts: np.ndarray, ends: np.ndarray
) -> np.ndarray:
    """Standard errors of a corrected least-squares fit, in the scaled columns xs (divide by the scale). Windows
    that share an end sample have correlated errors (the shared torque sample enters both integrals, the shared
    speed sample both speed changes with opposite signs): an MA(1) error, covariance s2*(I + rho*A)."""
    dof = y.size - xs.shape[1]
    s2 = float(resid @ resid) / dof
    adj = np.flatnonzero(ends[:-1] == starts[1:])
    rho = float(np.sum(resid[adj] * resid[adj + 1]) / (s2 * dof)) if adj.size else 0.0
    rho = min(max(rho, -0.5), 0.5)
    xtx_inv = np.linalg.inv(xs.T @ xs - xs.shape[0] * np.diag(eiv))
    meat = xs.T @ xs + rho * (xs[adj].T @ xs[adj + 1] + xs[adj + 1].T @ xs[adj])
    cov = s2 * (xtx_inv @ meat @ xtx_inv)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None))


FOLLOWER_BLOCK_DECAY = 30.0  # follower_speed's blocks: the heaviest-damped mode decays by at most exp(-this) in one


def follower_speed(t: np.ndarray, w: np.ndarray, hz: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """Speed of a load that follows the motor speed w through a spring and a damper, for each (hz, damping): the
    load's own resonance against a held motor and its damping ratio (below 1). The load's speed is w through the
    low-pass (2 zeta wa s + wa^2) / (s^2 + 2 zeta wa s + wa^2), driven by w linear between samples and integrated
    exactly (over interval lengths rounded to 0.1 %). Rows: samples; columns: one per (hz, damping); it starts
    with w[0] and no deflection."""
    wa = 2 * np.pi * np.asarray(hz, dtype=float)
    zeta = np.asarray(damping, dtype=float)
    lam = wa * (-zeta + 1j * np.sqrt(1.0 - zeta * zeta))
    beta = -0.5j / lam.imag
    # State: deflection d (motor minus load angle) and e = load speed - motor speed; with the motor's acceleration a
    # constant over an interval, d' = -e and e' = k d - c e - a. In the mode z of eigenvalue lam, (d, e) =
    # 2 Re((1, -lam) z) and z' = lam z + beta a, exactly: z(h) = exp(lam h) z(0) + beta a (exp(lam h) - 1) / lam.
    span = np.diff(t)
    # One map per interval length, lengths binned to 0.1 % (jittery real-time logs have no two alike)
    bins, which = np.unique(np.round(np.log(span) / 1e-3), return_inverse=True)
    decay = np.exp(np.exp(bins * 1e-3)[:, None] * lam)
    gain = beta * (decay - 1.0) / lam
    accel = np.diff(w) / span
    modes = np.zeros((t.size, *wa.shape), dtype=complex)
    # In blocks, z after each interval is M (z0 + cumsum(gain a / M)) with M the running product of the decays:
    # vectorised over a block's intervals, and short enough blocks keep 1 / M within exp(FOLLOWER_BLOCK_DECAY).
    block = FOLLOWER_BLOCK_DECAY / max(float(np.max(-lam.real)), 1e-9)
    cuts = np.searchsorted(np.cumsum(span), np.arange(block, float(np.sum(span)), block))
    z = np.zeros(wa.shape, dtype=complex)
    for lo, hi in zip(np.concatenate(([0], cuts)), np.concatenate((cuts, [span.size])), strict=True):
        if hi <= lo:
            continue
        m = np.cumprod(decay[which[lo:hi]], axis=0)
        modes[lo + 1 : hi + 1] = m * (z + np.cumsum(gain[which[lo:hi]] * accel[lo:hi, None] / m, axis=0))
        z = modes[hi]
    return -2.0 * (modes * lam).real + np.asarray(w, dtype=float)[:, None]


def follower_changes(
    t: np.ndarray,
    w: np.ndarray,
    starts: np.ndarray,
    ends: np.ndarray,
    hz: np.ndarray,
    damping: np.ndarray,
    max_rate: float,
) -> np.ndarray:
    """follower_speed's change over each window [starts, ends] (rows) for each (hz, damping) (columns), integrated
    over the windows' ends and samples between them at most max_rate apart (the load's resonance lies far below)."""
    due = np.zeros(t.size, dtype=bool)
    due[starts] = due[ends] = True
    due[0] = due[-1] = True
    ticks = np.floor((t - t[0]) * max_rate)
    due[1:] |= ticks[1:] != ticks[:-1]
    keep = np.flatnonzero(due)
    w_load = follower_speed(t[keep], w[keep], hz, damping)
    return w_load[np.searchsorted(keep, ends)] - w_load[np.searchsorted(keep, starts)]


def projected_fits(u: np.ndarray, v: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(coefficient, residual sum of squares) of v[:, g] on u[:, g] for every column g, with the columns `others`
    fitted alongside (projected out once for all)."""
    q, _r = np.linalg.qr(others / np.where(np.linalg.norm(others, axis=0) > 0, np.linalg.norm(others, axis=0), 1.0))
    pu, pv = u - q @ (q.T @ u), v - q @ (q.T @ v)
    uu, uv = np.sum(pu * pu, axis=0), np.sum(pu * pv, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        coef = np.where(uu > 0, uv / uu, 0.0)
    return coef, np.sum(pv * pv, axis=0) - coef * uv


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
