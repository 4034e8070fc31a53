"""What the model checks pass along (fit.checks): J, its uncertainty and the words for what they found so far.

Every check reads a Verdict and returns one; the fit's conclusion (fit.conclude) reads the last.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.tuning.fit.estimate import RateBound
from servotool.tuning.fit.regression import FitData, refit


@dataclass(frozen=True)
class Cause:
    """Why J or its uncertainty moved, in the operator's words."""

    words: str
    curable: bool  # stronger accelerations shrink what it adds to the uncertainty (a longer travel may cure it)
    found: bool = True  # named as the load's mechanics; False: a term too weak or too small to name (no cause of a
    #                     J at or below zero)


@dataclass(frozen=True)
class Floor:
    """An uncertainty of J that no fit sees (the torque reading's steps), added after every other test passed."""

    rel: float  # relative uncertainty of J it adds (in quadrature)
    step_pct: float  # the torque reading's step, % of rated
    signal_pct: float  # the RMS acceleration torque, % of rated


@dataclass(frozen=True)
class Verdict:
    """J as the checks so far leave it. A check may leave windows out (fit), add regressors (x), move J and widen its
    uncertainty; it says why in `fitted` (a model of mechanics outside the rigid one, J taken from it), `widening`
    (the uncertainty widened beyond that; a later check's replaces an earlier one's) or `remarks`, and refuses with
    `refuse` (no later check runs)."""

    fit: FitData  # the windows and regression J stands on
    x: np.ndarray  # the regressors of the model used (the fit's, with the columns checks added)
    j: float
    j_std: float
    resid: np.ndarray  # the model used's equation error per window (N*m*s)
    fitted: tuple[Cause, ...] = ()
    widening: Cause | None = None
    remarks: tuple[str, ...] = ()
    refuse: str = ""  # empty: usable (perhaps with a widened uncertainty)
    floor: Floor | None = None
    rate_bound: RateBound | None = None  # a share of j_std the sampling rate bounds, not the excitation

    @classmethod
    def of(cls, fit: FitData) -> Verdict:
        """The rigid fit's answer, before any check."""
        return cls(fit, fit.x, float(fit.theta[0]), fit.j_std, fit.y - fit.x @ fit.theta)

    @property
    def notes(self) -> tuple[str, ...]:
        """The operator's notes; one on the fitted models first, starting "off-model:" so reports can tell it."""
        off = [f"off-model: {'; '.join(c.words for c in self.fitted)}; inertia fitted with a model of it"]
        return (*(off if self.fitted else []), *self.remarks)

    @property
    def widened(self) -> str:
        """Why the uncertainty is wider than the rigid fit's (the words a refusal for it gives); empty if it is not."""
        return "; ".join(c.words for c in self.causes)

    @property
    def curable(self) -> bool:
        """Whether every cause of a widening is one that stronger accelerations shrink."""
        return all(c.curable for c in self.causes)

    @property
    def causes(self) -> tuple[Cause, ...]:
        return (*self.fitted, self.widening) if self.widening is not None else self.fitted

    @property
    def residual(self) -> tuple[float, float]:
        """RMS per window of the model used's equation error and of the torque integrals it explains (N*m*s)."""
        return float(np.sqrt(np.mean(self.resid**2))), float(np.sqrt(np.mean(self.fit.y**2)))


def take(
    fit: FitData,
    x: np.ndarray,
    before: tuple[float, float, np.ndarray],
    model_error: float,
    shared: np.ndarray | None = None,
) -> tuple[float, float, np.ndarray]:
    """(J, sigma, residual) of the fit over regressors x (shared: as regression.refit has it); sigma grows by
    model_error times the correction to J. `before` where that fit is singular."""
    found = refit(fit, x, shared)
    if found is None:
        return before
    j = float(found[0][0])
    return j, math.hypot(max(float(found[1][0]), before[1]), model_error * (j - before[0])), found[2]
