"""Numbers behind the tune charts, from the identification's trace and estimate: the model torque and the gains
with the room left to their limits (each move's own estimate comes with the estimate: InertiaEstimate.moves)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.model.codec import raw_to_eng
from servotool.tuning.fit.signals import RPM_TO_RAD_S
from servotool.tuning.identify import Result
from servotool.tuning.tune import TuneResult


def _zero_band(rpm: np.ndarray, noise_rpm: float) -> float:
    """The estimator's default zero-speed band."""
    noise = noise_rpm if math.isfinite(noise_rpm) else 0.0
    return max(0.02 * float(np.max(np.abs(rpm))) if rpm.size else 0.0, 3.0 * noise)


def model_torque_pct(result: Result, rated_torque_nm: float) -> np.ndarray:
    """The torque (% of rated) the fitted model says the motion took: J·dω/dt + Tc·sign(ω) + B·ω + Tg."""
    est = result.estimate
    assert est is not None
    t = np.asarray(result.trace.t, dtype=float)
    rpm = np.asarray(result.trace.aligned_speed(), dtype=float)
    w = rpm * RPM_TO_RAD_S
    band = _zero_band(rpm, est.speed_noise_rpm)
    sgn = np.where(rpm >= band, 1.0, np.where(rpm <= -band, -1.0, 0.0))
    dw = np.gradient(w, t) if t.size > 2 else np.zeros_like(w)
    coef = [
        0.0 if not math.isfinite(x) else x
        for x in (est.j_total_kgm2, est.coulomb_nm, est.viscous_nm_per_rad_s, est.load_torque_nm)
    ]
    torque = coef[0] * dw + coef[1] * sgn + coef[2] * w + coef[3]
    return torque / rated_torque_nm * 100.0


@dataclass(frozen=True)
class GainRow:
    role: str
    code: str
    old: float
    new: float
    unit: str
    low: float | None
    high: float | None

    @property
    def range_text(self) -> str:
        return f"{self.low:g}..{self.high:g}" if self.low is not None and self.high is not None else "?"

    @property
    def margin(self) -> tuple[float, str] | None:
        """The factor the new value may still change by before it meets the nearer limit, and which limit
        (1.0: at the limit, where a computed gain is clamped); None without a range."""
        if self.low is None or self.high is None or self.high <= self.low or self.new <= 0:
            return None
        to_max = self.high / self.new
        to_min = self.new / self.low if self.low > 0 else math.inf
        return (to_min, "min") if to_min < to_max else (to_max, "max")

    @property
    def margin_text(self) -> str:
        m = self.margin
        if m is None:
            return "?"
        factor, limit = m
        return f"at {limit}" if factor <= 1.0 + 1e-9 else f"×{factor:.3g} to {limit}"


def gain_rows(tune: TuneResult) -> list[GainRow]:
    rows = []
    for c in tune.proposal.gain_changes:
        e = c.entry
        low, high = (float(raw_to_eng(e, e.min)), float(raw_to_eng(e, e.max))) if e.max > e.min else (None, None)
        rows.append(GainRow(c.role, e.code, c.old, c.new, e.unit, low, high))
    return rows
