"""Host-side inertia identification from logged speed and torque (integral least squares).

Model (SI units, omega in rad/s, T in N*m):

    J * domega/dt = T - Tc * sign(omega) - B * omega - Tg

Tc is Coulomb friction, B viscous friction and Tg a constant load torque (gravity; positive Tg opposes positive
speed). Differentiating sparsely sampled, jittery speed is hopeless, so the equation is integrated over windows
[t_a, t_b] of consecutive samples instead:

    J * (omega_b - omega_a) + Tc * int(sign omega) + B * int(omega) + Tg * (t_b - t_a) = int(T)

with integrals of the piecewise-cubic (Hermite) interpolant over the actual timestamps: the trapezoid rule would
miss the curvature between slow samples (a ringing loop) and bias J. Windows never contain a sample inside the
zero-speed band, so sign(omega) is constant within a window (stiction and the noisy sign near standstill stay out
of the fit), and no window touches a torque step (a kink in speed or torque), which no interpolant can place
between slow samples, or spans a host's stall. The speed noise in omega_b - omega_a (a noisy regressor) is
corrected for.
The windows are disjoint, so only neighbours sharing an end sample have correlated errors; the covariance accounts
for that correlation (MA(1)), which keeps the reported uncertainty honest (overlapping "all pairs" windows would
report a smaller, dishonest one).

Tc and Tg are only separable when the log has motion in both directions: in one direction both act as the same
constant torque.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from servotool.tuning.fit.checks import Verdict, assess
from servotool.tuning.fit.regression import FitData
from servotool.tuning.fit.signals import (
    corrected_lstsq,
    cumulative_hermite,
    jackknife_std,
    kink_mask,
    ma1_std,
    move_ids,
    sign_windows,
    speed_noise_rpm,
    validate_log,
)

RPM_TO_RAD_S = math.pi / 30.0
GAP_INTERVALS = 6.0  # no window spans more median intervals (a stall: a cubic misses a ringing loop's swing)
KGCM2_TO_KGM2 = 1e-4


@dataclass(frozen=True)
class EstimatorSettings:
    """Acceptance thresholds and fit options; the defaults suit a 20-40 samples/s Modbus log."""

    min_samples: int = 20
    """Fewer samples than this are refused outright."""
    min_windows: int = 12
    """Fewer usable windows (outside the zero-speed band) than this are refused."""
    window_intervals: int | None = None
    """Sampling intervals per window. None: the smallest of 1..max_window_intervals that reaches min_excitation
    (the errors-in-variables bias on J shrinks with the square of the window length, but longer windows are fewer
    and lose the intervals left over at the end of each run)."""
    max_window_intervals: int = 6
    max_rel_uncertainty: float = 0.02
    """Refuse when the 1-sigma uncertainty of J_total exceeds this fraction of J_total. Equivalently the ratio's
    standard uncertainty may be at most 0.02 * (1 + ratio): +-0.02 at ratio 0, +-0.08 at ratio 3. Gain tuning
    tolerates ~10 % inertia error, so 2 % (1 sigma) leaves margin."""
    min_excitation: float = 10.0
    """Refuse when the speed changes within windows (RMS) are less than this many times the speed noise of a
    window (sqrt(2) * noise). Plain least squares would bias J low by about 1/excitation^2 (1 % at 10); the fit
    removes that bias with the estimated noise, so this bounds what an error in that estimate can cost."""
    max_rel_residual: float = 0.3
    """Refuse when RMS(equation error) / RMS(integrated torque) exceeds this: the model does not fit (backlash,
    compliance, a torque reading that is not the shaft torque)."""
    saturation_fraction: float = 0.98
    """A torque sample with |T| >= this * torque limit counts as saturated."""
    max_saturated_samples: int = 0
    """Refuse when more samples than this are saturated (a saturated drive no longer follows the test motion)."""
    kink_sigma: float = 5.0
    """A torque or speed sample further than this many noise sigmas off the line through its neighbours marks a
    torque step (start/end of an acceleration: a kink in speed); the intervals on both sides are left out. No
    interpolant can integrate a step that falls somewhere between two slow samples, and its error is
    correlated with the window's speed change, which biases J low by about 2 % at 25-40 samples/s. Speed shows
    the kink even when the torque step is buried in torque noise."""
    torque_noise_floor_pct: float = 0.05
    """Floor of the estimated torque noise (% of rated) used for the kink test, so clean data is not all kinks."""
    zero_band_rpm: float | None = None
    """Samples with |speed| below this are left out. None: max(2 % of the peak speed, 3 * speed noise)."""
    speed_noise_rpm: float | None = None
    """Speed measurement noise (1 sigma). None: estimated from the log (floored at 0.1 rpm)."""
    fit_viscous: bool = True
    """Fit B; with False, B is held at 0."""
    fit_load_torque: bool = True
    """Fit Tg; with False, Tg is held at 0 (horizontal axis) and one-direction logs become acceptable."""
    max_condition: float = 1e8
    """Refuse when the column-scaled regression matrix is worse conditioned than this."""
    min_jackknife_moves: int = 4
    """With at least this many separate moves in the log, the uncertainty is at least the delete-one-move
    jackknife's (honest when errors are correlated within a move); below it only the least-squares formula."""


@dataclass(frozen=True)
class InertiaEstimate:
    """Result of `estimate_inertia`. Values are NaN where the fit did not get far enough to compute them."""

    ok: bool
    reason: str
    """Empty when ok; otherwise why the result must not be used, in words for the operator."""
    j_total_kgm2: float
    j_std_kgm2: float
    load_ratio: float
    """J_load / J_motor = J_total / J_motor - 1."""
    ratio_std: float
    """Standard uncertainty (1 sigma, from the least-squares covariance) of load_ratio."""
    coulomb_nm: float
    coulomb_std_nm: float
    viscous_nm_per_rad_s: float
    viscous_std_nm_per_rad_s: float
    load_torque_nm: float
    """Constant load torque (gravity); positive opposes positive speed."""
    load_torque_std_nm: float
    residual_rms_nms: float
    """RMS equation error per window of the model the checks settled on, in N*m*s."""
    residual_rel: float
    """residual_rms_nms / RMS of the windows' torque integrals."""
    excitation: float
    """RMS speed change per window / (sqrt(2) * speed noise); see EstimatorSettings.min_excitation."""
    speed_noise_rpm: float
    n_samples: int
    n_windows: int
    n_saturated: int
    window_intervals: int
    """Sampling intervals per window actually used (0 if no windows were formed)."""
    n_kinks: int
    """Samples recognised as torque steps (kinks) and left out with their neighbouring intervals."""
    condition: float
    notes: tuple[str, ...] = field(default_factory=tuple)
    advice: str = ""
    """What would cure a refusal, in general terms; the caller that planned the motion may say it in its own."""
    shortfall: float = math.nan
    """How many times short of its limit a refusal that more excitation would cure fell (else NaN)."""


def estimate_inertia(
    t_s: np.ndarray | list[float],
    speed_rpm: np.ndarray | list[float],
    torque_pct: np.ndarray | list[float],
    *,
    rated_torque_nm: float,
    rotor_inertia_kgcm2: float,
    torque_limit_pct: float | None = None,
    settings: EstimatorSettings | None = None,
) -> InertiaEstimate:
    """Fit J, Coulomb, viscous and load torque to a logged motion; refuse (ok=False) rather than guess.

    t_s: sample times in s (strictly increasing, any spacing); speed_rpm: motor speed; torque_pct: torque in % of
    rated torque (same sign convention as speed). torque_limit_pct: the drive's active torque limit, used to detect
    saturation (None: not checked). Raises ValueError only for malformed input (shapes, non-finite values,
    non-increasing time, non-positive motor data).
    """
    cfg = settings or EstimatorSettings()
    t = np.asarray(t_s, dtype=float)
    rpm = np.asarray(speed_rpm, dtype=float)
    pct = np.asarray(torque_pct, dtype=float)
    validate_log(t, rpm, pct, rated_torque_nm, rotor_inertia_kgcm2, torque_limit_pct)
    jm = rotor_inertia_kgcm2 * KGCM2_TO_KGM2
    r = _Partial(n_samples=int(t.size))
    try:
        _check_samples(r, pct, torque_limit_pct, cfg)
        sig = _signals(t, rpm, pct, rated_torque_nm, cfg, r)
        fit = _excited_fit(sig, _windows(sig, cfg, r), cfg, r)
    except _Refused as exc:
        return r.refuse(str(exc), exc.advice)
    verdict = assess(
        FitData(
            t=t,
            w=sig.w,
            kink=sig.kink,
            position=sig.cum_w,
            starts=fit.starts,
            ends=fit.ends,
            torque=sig.torque,
            x=fit.x,
            y=fit.y,
            eiv=fit.eiv,
            groups=sig.moves[fit.starts],
            names=tuple(fit.names),
            theta=fit.theta,
            j_std=float(fit.std[0]),
            min_jackknife_moves=cfg.min_jackknife_moves,
            rated_nm=rated_torque_nm,
            jm=jm,
            max_rel=cfg.max_rel_uncertainty,
        )
    )
    return _conclude(r, fit, verdict, jm, cfg)


class _Refused(Exception):
    """The fit stops here; the message is the reason, in words for the operator, and `advice` what would cure it."""

    def __init__(self, reason: str, advice: str = "") -> None:
        super().__init__(reason)
        self.advice = advice


@dataclass(frozen=True)
class _Signals:
    """The log in SI units, with what the windows and integrals need."""

    t: np.ndarray
    rpm: np.ndarray
    w: np.ndarray
    torque: np.ndarray
    noise_w: float
    band: float
    kink: np.ndarray
    cum_t: np.ndarray
    cum_w: np.ndarray
    moves: np.ndarray


@dataclass(frozen=True)
class _Fit:
    """The corrected least-squares fit over the chosen windows."""

    names: list[str]
    starts: np.ndarray
    ends: np.ndarray
    x: np.ndarray
    y: np.ndarray
    eiv: np.ndarray
    theta: np.ndarray
    std: np.ndarray


def _check_samples(r: _Partial, pct: np.ndarray, torque_limit_pct: float | None, cfg: EstimatorSettings) -> None:
    if r.n_samples < cfg.min_samples:
        raise _Refused(f"too few samples ({r.n_samples} < {cfg.min_samples}); log a longer motion or sample faster")
    if torque_limit_pct is not None:
        r.n_saturated = int(np.count_nonzero(np.abs(pct) >= cfg.saturation_fraction * torque_limit_pct))
        if r.n_saturated > cfg.max_saturated_samples:
            raise _Refused(
                f"torque saturated: {r.n_saturated} samples at the {torque_limit_pct:g} % torque limit; "
                "use gentler acceleration or a lower test speed"
            )


def _signals(
    t: np.ndarray, rpm: np.ndarray, pct: np.ndarray, rated_torque_nm: float, cfg: EstimatorSettings, r: _Partial
) -> _Signals:
    """Noise, zero-speed band, kinks (torque steps) and the Hermite integrals of torque and speed."""
    noise_rpm = cfg.speed_noise_rpm if cfg.speed_noise_rpm is not None else speed_noise_rpm(t, rpm)
    r.speed_noise_rpm = noise_rpm
    peak = float(np.max(np.abs(rpm)))
    band = cfg.zero_band_rpm if cfg.zero_band_rpm is not None else max(0.02 * peak, 3.0 * noise_rpm)
    w = rpm * RPM_TO_RAD_S
    torque = pct / 100.0 * rated_torque_nm
    kink = kink_mask(t, rpm, pct, noise_rpm, cfg.kink_sigma, cfg.torque_noise_floor_pct, GAP_INTERVALS)
    r.n_kinks = int(np.count_nonzero(kink))
    return _Signals(
        t=t,
        rpm=rpm,
        w=w,
        torque=torque,
        noise_w=noise_rpm * RPM_TO_RAD_S,
        band=band,
        kink=kink,
        cum_t=cumulative_hermite(t, torque, kink),
        cum_w=cumulative_hermite(t, w, kink),
        moves=move_ids(rpm, band),
    )


def _windows(sig: _Signals, cfg: EstimatorSettings, r: _Partial) -> tuple[np.ndarray, np.ndarray]:
    """(starts, ends) of the windows: the shortest that give enough excitation, else the most excited."""
    # Longer windows raise the speed change per window against the (fixed) noise of its two end samples.
    ks = [cfg.window_intervals] if cfg.window_intervals is not None else list(range(1, cfg.max_window_intervals + 1))
    best = (np.zeros(0, dtype=int), np.zeros(0, dtype=int))
    for k in ks:
        starts, ends = sign_windows(sig.rpm, sig.band, sig.kink, max(1, k))
        r.n_windows = int(starts.size)
        if r.n_windows < cfg.min_windows:
            break
        dw = sig.w[ends] - sig.w[starts]
        excitation = float(np.sqrt(np.mean(dw**2)) / (math.sqrt(2.0) * sig.noise_w))
        if k == ks[0] or excitation > r.excitation:
            r.excitation, r.window_intervals, best = excitation, k, (starts, ends)
        if excitation >= cfg.min_excitation:
            break
    if r.window_intervals == 0:
        raise _Refused(
            f"too few usable windows ({r.n_windows} < {cfg.min_windows}) outside the zero-speed band "
            f"of {sig.band:.3g} rpm and away from torque steps; log a longer motion at higher speed"
        )
    r.n_windows = int(best[0].size)
    return best


def _excited_fit(sig: _Signals, windows: tuple[np.ndarray, np.ndarray], cfg: EstimatorSettings, r: _Partial) -> _Fit:
    """The fit, refused first where the windows' speed changes are too close to the speed noise; made anyway to tell
    how far short the data fell (`shortfall`): the excitation passes its limit well before the precision does."""
    low = r.excitation < cfg.min_excitation
    try:
        fit: _Fit | None = _fit(sig, windows, cfg, r)
    except _Refused:
        if not low:
            raise
        fit = None
    if fit is not None and not low:
        return fit
    rel = fit.std[0] / fit.theta[0] if fit is not None and fit.theta[0] > 0 else 0.0
    r.shortfall = max(cfg.min_excitation / max(r.excitation, 1e-9), rel / cfg.max_rel_uncertainty)
    raise _Refused(
        f"too little acceleration: speed changes are only {r.excitation:.1f}x the speed noise "
        f"(need {cfg.min_excitation:g}x)",
        "use faster accelerations or a higher test speed",
    )


def _fit(sig: _Signals, windows: tuple[np.ndarray, np.ndarray], cfg: EstimatorSettings, r: _Partial) -> _Fit:
    """Corrected least squares over the windows, with an honest (MA(1), jackknife) uncertainty."""
    starts, ends = windows
    t, w = sig.t, sig.w
    dw, dt, sgn = w[ends] - w[starts], t[ends] - t[starts], np.sign(w[starts])
    y = sig.cum_t[ends] - sig.cum_t[starts]
    both = bool(np.count_nonzero(sgn > 0) >= 3 and np.count_nonzero(sgn < 0) >= 3)
    if cfg.fit_load_torque and not both:
        raise _Refused(
            "motion in one direction only: Coulomb friction and load (gravity) torque cannot be "
            "separated; run the test with --direction both"
        )
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
        raise _Refused(f"too few usable windows ({r.n_windows}) for {p} unknowns")
    scale = np.linalg.norm(x, axis=0)
    scale[scale == 0] = 1.0
    xs = x / scale
    sv = np.linalg.svd(xs, compute_uv=False)
    r.condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if r.condition > cfg.max_condition:
        raise _Refused(
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
    return _Fit(names=names, starts=starts, ends=ends, x=x, y=y, eiv=eiv, theta=theta, std=std)


def _conclude(r: _Partial, fit: _Fit, verdict: Verdict, jm: float, cfg: EstimatorSettings) -> InertiaEstimate:
    """The estimate with the model check's J, notes and the refusals that only the whole result can decide."""
    est = dict(zip(fit.names, fit.theta, strict=True))
    err = dict(zip(fit.names, fit.std, strict=True))
    j = float(verdict.j)
    r.j, r.j_std = j, float(verdict.j_std)
    r.ratio, r.ratio_std = j / jm - 1.0, r.j_std / jm
    r.tc, r.tc_std = float(est["Tc"]), float(err["Tc"])
    r.b, r.b_std = float(est.get("B", 0.0)), float(err.get("B", 0.0))
    r.tg, r.tg_std = float(est.get("Tg", 0.0)), float(err.get("Tg", 0.0))
    # The model the checks settled on is what must fit (the windows clear of lost motion, a two-mass load's)
    r.res_rms, y_rms = verdict.residual
    r.res_rel = r.res_rms / y_rms if y_rms > 0 else math.inf
    if not cfg.fit_load_torque:
        r.notes.append(
            "load torque not fitted (one direction only, or told there is none): 'coulomb' is Coulomb + load torque"
        )
    if r.tc < -3 * r.tc_std:
        r.notes.append("negative Coulomb friction: check the torque sign convention against the speed")
    r.notes.extend(verdict.notes)
    if j <= 0:
        return r.refuse("non-physical result (inertia <= 0): check that torque and speed share a sign convention")
    if r.res_rel > cfg.max_rel_residual:
        return r.refuse(
            f"model does not fit the data (relative residual {r.res_rel:.2f} > {cfg.max_rel_residual:g}): "
            "backlash, compliance or a torque reading that is not shaft torque"
        )
    if verdict.refuse:
        return r.refuse(verdict.refuse)
    rel = r.j_std / j
    if rel > cfg.max_rel_uncertainty:
        # noise sorting and backlash weigh less in a stronger motion (0.1 rad, ratio 2: within 1 % at 5.5 rev)
        r.shortfall = rel / cfg.max_rel_uncertainty if not verdict.widened or verdict.curable else math.nan
        said = f"inertia too uncertain ({100 * rel:.1f} % of J_total > {100 * cfg.max_rel_uncertainty:g} %)"
        if verdict.widened:
            return r.refuse(f"{said}: {verdict.widened}")
        return r.refuse(said, "use stronger accelerations or more moves")
    return r.result(ok=True, reason="")


@dataclass
class _Partial:
    """Accumulates result fields so refusals at any stage report what is known so far."""

    n_samples: int
    n_windows: int = 0
    n_saturated: int = 0
    n_kinks: int = 0
    window_intervals: int = 0
    speed_noise_rpm: float = math.nan
    excitation: float = math.nan
    condition: float = math.nan
    j: float = math.nan
    j_std: float = math.nan
    ratio: float = math.nan
    ratio_std: float = math.nan
    tc: float = math.nan
    tc_std: float = math.nan
    b: float = math.nan
    b_std: float = math.nan
    tg: float = math.nan
    tg_std: float = math.nan
    res_rms: float = math.nan
    res_rel: float = math.nan
    notes: list[str] = field(default_factory=list)
    shortfall: float = math.nan

    def refuse(self, reason: str, advice: str = "") -> InertiaEstimate:
        return self.result(ok=False, reason=reason, advice=advice)

    def result(self, *, ok: bool, reason: str, advice: str = "") -> InertiaEstimate:
        return InertiaEstimate(
            ok=ok,
            reason=reason,
            j_total_kgm2=self.j,
            j_std_kgm2=self.j_std,
            load_ratio=self.ratio,
            ratio_std=self.ratio_std,
            coulomb_nm=self.tc,
            coulomb_std_nm=self.tc_std,
            viscous_nm_per_rad_s=self.b,
            viscous_std_nm_per_rad_s=self.b_std,
            load_torque_nm=self.tg,
            load_torque_std_nm=self.tg_std,
            residual_rms_nms=self.res_rms,
            residual_rel=self.res_rel,
            excitation=self.excitation,
            speed_noise_rpm=self.speed_noise_rpm,
            n_samples=self.n_samples,
            n_windows=self.n_windows,
            n_saturated=self.n_saturated,
            n_kinks=self.n_kinks,
            window_intervals=self.window_intervals,
            condition=self.condition,
            notes=tuple(self.notes),
            advice=advice,
            shortfall=self.shortfall,
        )
