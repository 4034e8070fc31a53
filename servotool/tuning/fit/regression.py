"""Fourth stage of the fit: the momentum balance over the windows, by least squares corrected for the noisy speed.

    J * (omega_b - omega_a) + Tc * int(sign omega) + B * int(omega) + Tg * (t_b - t_a) = int(T)

over each window [t_a, t_b] (SI units; Tc Coulomb friction, B viscous, Tg a constant load torque, positive opposing
positive speed). The speed noise in omega_b - omega_a (a noisy regressor) would bias J low; its expected variance is
taken out of X'X. Windows that share an end sample have correlated errors (MA(1)), and errors that repeat within a
move are seen by a delete-one-move jackknife: both enter the uncertainty, which must bound the error. Tc and Tg are
separable only with motion in both directions.

FitData is what the fit saw, and refit the same fit with more columns or fewer windows: the model checks
(fit.checks) are built on them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit.estimate import EstimatorSettings, Partial, Refused
from servotool.tuning.fit.signals import Signals, stall_words


@dataclass(frozen=True)
class Regression:
    """The corrected least-squares fit over the chosen windows."""

    names: list[str]
    starts: np.ndarray
    ends: np.ndarray
    x: np.ndarray
    y: np.ndarray
    eiv: np.ndarray
    theta: np.ndarray
    std: np.ndarray


def regress(sig: Signals, windows: tuple[np.ndarray, np.ndarray], cfg: EstimatorSettings, r: Partial) -> Regression:
    """The fit, refused first where the windows' speed changes are too close to the speed noise; made anyway to tell
    how far short the data fell (`shortfall`): the excitation passes its limit well before the precision does."""
    low = r.excitation < cfg.min_excitation
    try:
        fit: Regression | None = _least_squares(sig, windows, cfg, r)
    except Refused:
        if not low:
            raise
        fit = None
    if fit is not None and not low:
        return fit
    rel = fit.std[0] / fit.theta[0] if fit is not None and fit.theta[0] > 0 else 0.0
    r.shortfall = max(cfg.min_excitation / max(r.excitation, 1e-9), rel / cfg.max_rel_uncertainty)
    raise Refused(
        f"too little acceleration: speed changes are only {r.excitation:.1f}x the speed noise "
        f"(need {cfg.min_excitation:g}x)",
        "use faster accelerations or a higher test speed",
    )


MIN_WINDOWS_EACH_WAY = 3  # windows in each direction that separate Coulomb friction from a load torque
MOVED_SHARE = 0.05  # a direction the speed went in: this share of the samples beyond the zero band that way


def one_way(sig: Signals, forward: int, reverse: int) -> str:
    """Why the windows fall short in one direction: the motion went one way only (the user's --direction), or it went
    both ways and the windows that way were too few (a host's stalls and late samples cut them: named where the log
    shows a stall)."""
    fwd, rev = np.count_nonzero(sig.rpm >= sig.band), np.count_nonzero(sig.rpm <= -sig.band)
    if min(fwd, rev) < MOVED_SHARE * sig.rpm.size:
        return (
            "motion in one direction only: Coulomb friction and load (gravity) torque cannot be separated; run the "
            "test with --direction both"
        )
    stalled = stall_words(sig.t, sig.rpm, sig.own)
    return (
        f"too few usable windows in the {'reverse' if reverse < forward else 'forward'} moves ({forward} forward, "
        f"{reverse} reverse; {MIN_WINDOWS_EACH_WAY} each way needed) to separate Coulomb friction from load torque"
        + (f": {stalled} cut them; run it again on a quieter host" if stalled else "; log more moves")
    )


def _least_squares(
    sig: Signals, windows: tuple[np.ndarray, np.ndarray], cfg: EstimatorSettings, r: Partial
) -> Regression:
    """Corrected least squares over the windows, with an honest (MA(1), jackknife) uncertainty."""
    starts, ends = windows
    t, w = sig.t, sig.w
    dw, dt, sgn = w[ends] - w[starts], t[ends] - t[starts], np.sign(w[starts])
    y = sig.cum_t[ends] - sig.cum_t[starts]
    forward, reverse = int(np.count_nonzero(sgn > 0)), int(np.count_nonzero(sgn < 0))
    if cfg.fit_load_torque and min(forward, reverse) < MIN_WINDOWS_EACH_WAY:
        raise Refused(one_way(sig, forward, reverse))
    names, cols = ["J", "Tc"], [dw, sgn * dt]
    if cfg.fit_viscous:
        names.append("B")
        cols.append(sig.cum_w[ends] - sig.cum_w[starts])
    if cfg.fit_load_torque:
        names.append("Tg")
        cols.append(dt)
    x = np.column_stack(cols)
    p = x.shape[1]
    if r.n_windows <= p + 2:
        raise Refused(f"too few usable windows ({r.n_windows}) for {p} unknowns")
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    xs = x / scale
    sv = np.linalg.svd(xs, compute_uv=False)
    r.condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if r.condition > cfg.max_condition:
        raise Refused(
            f"regression ill-conditioned (condition {r.condition:.3g}): the motion does not separate "
            "inertia from friction and load torque; vary speed and acceleration in both directions"
        )
    # Speed noise in the regressor dw (variance 2 * noise^2 per window) inflates X'X and biases J low by about
    # 1/excitation^2; subtracting its expectation removes that bias (corrected least squares).
    eiv = np.zeros(p)
    eiv[0] = 2.0 * sig.noise_w**2 / scale[0] ** 2
    theta = corrected_lstsq(xs, y, eiv) / scale
    resid = y - x @ theta
    std = ma1_std(xs, y, eiv, resid, starts, ends) / scale
    # Errors the noise model misses (trapezoid error at a torque step, loop transients at slow sampling) repeat
    # within a move but differ between moves: a delete-one-move jackknife sees them, the formula does not.
    std = np.maximum(std, jackknife_std(xs, y, eiv, sig.moves[starts], cfg.min_jackknife_moves) / scale)
    return Regression(names=names, starts=starts, ends=ends, x=x, y=y, eiv=eiv, theta=theta, std=std)


@dataclass(frozen=True)
class FitData:
    """What the estimator's fit saw: samples, windows, the regression and its solution (unscaled)."""

    t: np.ndarray
    rpm: np.ndarray  # the speed as logged
    pct: np.ndarray  # the torque as logged, % of rated
    torque_step_pct: float  # the torque reading's resolution, % of rated (0: finer or unknown)
    torque_noise_pct: float  # the torque reading's error per sample (1 sigma, % of rated), its steps' included
    w: np.ndarray  # rad/s
    kink: np.ndarray
    position: np.ndarray  # rad at each sample (fit.signals.anchored)
    starts: np.ndarray
    ends: np.ndarray
    torque: np.ndarray  # N*m
    x: np.ndarray  # columns: J (dw), then friction and load terms
    y: np.ndarray
    eiv: np.ndarray  # regressor-noise variance per row of x scaled to unit column norms
    groups: np.ndarray  # move number of each window (for the jackknife)
    names: tuple[str, ...]  # the parameters in x's columns and theta: J, Tc, then B and Tg where fitted
    theta: np.ndarray
    j_std: float
    min_jackknife_moves: int
    rated_nm: float
    jm: float  # the motor's inertia, kg*m^2
    max_rel: float = 0.02  # the estimator's limit on sigma / J (a widening names its cause only if it crosses it)
    cut: np.ndarray | None = None  # per sampling interval: a speed corner lies in it (signals.corner_cuts)
    own: np.ndarray | None = None  # per sampling interval: the sampler's own pause in it, s (signals.paused_within)


def fit_data(sig: Signals, reg: Regression, cfg: EstimatorSettings, rated_nm: float, jm: float) -> FitData:
    """What the fit saw, for the model checks: the signals, the windows and the regression's solution."""
    return FitData(
        t=sig.t,
        rpm=sig.rpm,
        pct=sig.pct,
        torque_step_pct=sig.torque_step_pct,
        torque_noise_pct=sig.torque_noise_pct,
        w=sig.w,
        kink=sig.kink,
        position=sig.position,
        starts=reg.starts,
        ends=reg.ends,
        torque=sig.torque,
        x=reg.x,
        y=reg.y,
        eiv=reg.eiv,
        groups=sig.moves[reg.starts],
        names=tuple(reg.names),
        theta=reg.theta,
        j_std=float(reg.std[0]),
        min_jackknife_moves=cfg.min_jackknife_moves,
        rated_nm=rated_nm,
        jm=jm,
        max_rel=cfg.max_rel_uncertainty,
        cut=sig.cut,
        own=sig.own,
    )


def refit(
    fit: FitData, x: np.ndarray, shared: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(parameters, their sigmas, residual) of the fit with extra columns after the estimator's; None if singular.
    shared: per window (rows) and column of x, the expected product of that regressor's noise with the noise of the
    torque integral (a column computed from the same torque samples), taken out of X'y as eiv is out of X'X."""
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    xs = x / scale
    eiv = np.concatenate([fit.eiv, np.zeros(x.shape[1] - fit.eiv.size)])
    cross = None if shared is None else shared / scale
    try:
        theta = corrected_lstsq(xs, fit.y, eiv, cross) / scale
        resid = fit.y - x @ theta
        dof = max(1, x.shape[0] - x.shape[1])
        cov = float(resid @ resid) / dof * np.linalg.inv(xs.T @ xs - xs.shape[0] * np.diag(eiv))
    except np.linalg.LinAlgError:
        return None
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / scale
    std = np.maximum(std, jackknife_std(xs, fit.y, eiv, fit.groups, fit.min_jackknife_moves, cross) / scale)
    return theta, std, resid


def corrected_lstsq(xs: np.ndarray, y: np.ndarray, eiv: np.ndarray, cross: np.ndarray | None = None) -> np.ndarray:
    """Least squares with the expected regressor-noise variance per row (eiv) taken out of X'X, and (cross: per row
    and column) the expected product of a regressor's noise with y's out of X'y."""
    xty = xs.T @ y if cross is None else xs.T @ y - np.sum(cross, axis=0)
    return np.linalg.solve(xs.T @ xs - xs.shape[0] * np.diag(eiv), xty)


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


def jackknife_std(
    xs: np.ndarray,
    y: np.ndarray,
    eiv: np.ndarray,
    groups: np.ndarray,
    min_groups: int,
    cross: np.ndarray | None = None,
) -> np.ndarray:
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
            thetas.append(corrected_lstsq(xs[keep], y[keep], eiv, None if cross is None else cross[keep]))
        except np.linalg.LinAlgError:  # the rest cannot determine the parameters: no honest bound
            return np.full(xs.shape[1], np.inf)
    th = np.asarray(thetas)
    return np.sqrt((g - 1) / g * np.sum((th - th.mean(axis=0)) ** 2, axis=0))


def projected_fits(u: np.ndarray, v: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(coefficient, residual sum of squares) of v[:, g] on u[:, g] for every column g, with the columns `others`
    fitted alongside (projected out once for all)."""
    q, _r = np.linalg.qr(others / np.where(np.linalg.norm(others, axis=0) > 0, np.linalg.norm(others, axis=0), 1.0))
    pu, pv = u - q @ (q.T @ u), v - q @ (q.T @ v)
    uu, uv = np.sum(pu * pu, axis=0), np.sum(pu * pv, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        coef = np.where(uu > 0, uv / uu, 0.0)
    return coef, np.sum(pv * pv, axis=0) - coef * uv
