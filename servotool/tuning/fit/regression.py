"""What the inertia fit saw (tuning.fit.estimate), and the fit again with more columns or fewer windows: shared by the
checks on the rigid model (tuning.fit.checks, tuning.fit.lost_motion)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit.signals import corrected_lstsq, jackknife_std

MODEL_ERROR_DIVISOR = 3.0  # a correction by an extended model counts as uncertain by a third of its size


@dataclass(frozen=True)
class FitData:
    """What the estimator's fit saw: samples, windows, the regression and its solution (unscaled)."""

    t: np.ndarray
    w: np.ndarray  # rad/s
    kink: np.ndarray
    position: np.ndarray  # rad, integral of w at each sample
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


def refit(fit: FitData, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(parameters, their sigmas, residual) of the fit with extra columns after the estimator's; None if singular."""
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    xs = x / scale
    eiv = np.concatenate([fit.eiv, np.zeros(x.shape[1] - fit.eiv.size)])
    try:
        theta = corrected_lstsq(xs, fit.y, eiv) / scale
        resid = fit.y - x @ theta
        dof = max(1, x.shape[0] - x.shape[1])
        cov = float(resid @ resid) / dof * np.linalg.inv(xs.T @ xs - xs.shape[0] * np.diag(eiv))
    except np.linalg.LinAlgError:
        return None
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None)) / scale
    std = np.maximum(std, jackknife_std(xs, fit.y, eiv, fit.groups, fit.min_jackknife_moves) / scale)
    return theta, std, resid
