"""Numbers behind the tune charts, recomputed from the identification's trace and estimate: the model torque,
each move's own estimate, the gains with the room left to their limits."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from servotool.model.codec import raw_to_eng
from servotool.model.profile import Profile
from servotool.tuning.fit import EstimatorSettings, estimate_inertia
from servotool.tuning.fit.signals import RPM_TO_RAD_S, move_ids
from servotool.tuning.identify import Result
from servotool.tuning.tune import TuneResult

MIN_MOVE_SAMPLES = 6


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
class MoveEstimate:
    move: int  # 1-based, in the order run
    direction: int  # +1 forward, -1 reverse
    ratio: float  # this move's own J_load/J_motor
    ratio_std: float  # its standard uncertainty (1 sigma)
    samples: int


def move_estimates(result: Result, profile: Profile) -> list[MoveEstimate]:
    """Each move fitted on its own by the same estimator (windows, kinks, noise as in the whole fit); in one
    direction friction, viscous and load torque act as one constant, so only J and that constant are fitted."""
    est, motor = result.estimate, profile.motor
    if est is None or motor is None or not math.isfinite(est.j_total_kgm2) or len(result.trace.t) < 3:
        return []
    t = np.asarray(result.trace.t, dtype=float)
    rpm = np.asarray(result.trace.aligned_speed(), dtype=float)
    torque = np.asarray(result.trace.torque, dtype=float)
    band = _zero_band(rpm, est.speed_noise_rpm)
    ids = move_ids(rpm, band)
    cfg = EstimatorSettings(
        min_samples=MIN_MOVE_SAMPLES,
        min_windows=3,
        window_intervals=est.window_intervals or None,
        max_rel_uncertainty=math.inf,
        min_excitation=0.0,
        max_rel_residual=math.inf,
        fit_viscous=False,
        fit_load_torque=False,
        zero_band_rpm=band,
        speed_noise_rpm=est.speed_noise_rpm if math.isfinite(est.speed_noise_rpm) else None,
        max_condition=math.inf,
        min_jackknife_moves=1 << 30,
    )
    out: list[MoveEstimate] = []
    for k in np.unique(ids):
        idx = np.flatnonzero(ids == k)
        direction = int(np.sign(np.median(rpm[idx])))
        if idx.size < MIN_MOVE_SAMPLES or direction == 0:
            continue
        lo, hi = max(0, int(idx[0]) - 1), min(t.size, int(idx[-1]) + 2)  # a sample of rest either side
        one = estimate_inertia(
            t[lo:hi],
            rpm[lo:hi],
            torque[lo:hi],
            rated_torque_nm=motor.rated_torque_nm,
            rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
            settings=cfg,
        )
        if one.ok and math.isfinite(one.load_ratio):
            out.append(MoveEstimate(len(out) + 1, direction, one.load_ratio, one.ratio_std, int(idx.size)))
    return out


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
