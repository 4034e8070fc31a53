"""Is the rigid model right for this load? Consistency checks on the inertia fit (tuning.fit.estimate).

Mechanics outside the model (a compliant coupling, backlash, gravity that changes with position, cogging) leave
the fit's noise-based uncertainty tight while the answer is wrong. These checks see them:

- lost motion (tuning.fit.lost_motion): where the windows clear of the spans in which the motor may have turned without
  its load give a J 3 sigmas apart from the whole fit's, they alone are fitted from there on, flagged ("lost
  motion (backlash?) where the torque reverses"), with what a margin twice as wide still changes counted as
  uncertain.
- the load torque over the travel: the fit is repeated with a load torque that varies (quadratically) with the
  position (integrated speed). Where the variation is significant, the load varies over the travel and the
  extended model's inertia is used (an arm on a gear: the constant-torque model biased J by 10-40 %); where the
  dependence differs between forward and reverse moves, half its correction counts as uncertain (backlash also
  looks like such a load, and the model then moves J the wrong way).
- a resonance: where the sampling resolves it, the fit is repeated with the load's speed following the motor's
  through a spring and damper (the two-mass model, the motor's inertia known), over a grid of the load's resonance
  and damping. Where a lightly damped coupling explains the data far better than the rigid load and a heavily
  damped one (a lag, which rigid loads show too), its inertia is used, flagged with the resonance
  ("resonance near N Hz"), and a third of its correction counts as uncertain. Otherwise:
- compliance: the fit is repeated with a term for a spring between motor and load (the load's speed lags the
  motor's by the deflection's rate, which follows the torque's rate of change); where it is significant, the
  extended model's inertia is used, flagged with the resonance it implies ("resonance near N Hz"), and a third of
  its correction is added to the uncertainty (the quasi-static term is approximate). A hint of the term (beyond
  two sigmas, implying a resonance below the sampling rate) keeps the rigid answer but adds the whole change it
  would make; a refusal names the resonance only where the hint took the uncertainty over the limit. Short of
  that, the term cannot tell a stiff coupling from a rigid load: its column has the shape of the integration's own
  curvature correction, and on rigid loads at slow lines it picks up that correction's error near torque steps
  and at the stops (beyond half a sigma in half the runs, beyond two in a fifth to a third). So the rigid answer
  keeps the uncertainty it has with a free spring term, without words: a 100 Hz coupling at ratio 10 biased J by
  1.1-1.4 % with its term at -0.4 sigma.
- subsets (tuning.fit.subsets): J is taken from each subset of the windows with the friction and load fitted on all of
  them (forward/reverse x accelerating/braking, the start/middle/end of the travel, weak/medium/strong
  accelerations). Where the subsets disagree more than their uncertainties allow, the uncertainty is widened by
  the Birge ratio sqrt(chi2/dof); where they disagree grossly (by more than GROSS_SPREAD of J, well beyond their
  uncertainties) the result is refused. Accelerations that disagree no more than the speed noise can make them
  (subsets.points_off_model) widen it without an off-model note.
  Backlash the observer misses shows as a lower J while braking or a higher one at weak accelerations, a compliant
  coupling as J that differs between the phases of a move.

The returned notes start with "off-model:" so reports can tell them from others. Only J is corrected: the
friction and load torque the estimator reports stay the rigid fit's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from servotool.tuning.fit.lost_motion import clear_of_lost_motion
from servotool.tuning.fit.regression import MODEL_ERROR_DIVISOR, FitData, projected_fits, refit
from servotool.tuning.fit.signals import cumulative_hermite
from servotool.tuning.fit.subsets import Windows, cause, points_off_model, torque_step, unblamed, worst_subsets

POSITION_SIGMA = 4.0  # a position-dependent load term counts when beyond this many sigmas ...
POSITION_MIN_PCT = 2.0  # ... and it changes the load by at least this % of rated torque over the travel
COMPLIANCE_SIGMA = 4.0  # a compliance term counts when beyond this many sigmas
COMPLIANCE_MIN_SHIFT = 0.01  # ... and moves J by more than this fraction (and 2 sigma)
MIN_COMPLIANT_RATIO = 0.3  # below this load ratio there is too little load behind a coupling to matter
COMPLIANCE_HINT_SIGMA = 2.0  # beyond this many it widens the uncertainty by what it would change J (one-sided 2 sigma:
#                             at 0.5 the hint widened a third of rigid loads on slow lines, 79 of 479 bench runs refused
#                             for 'perhaps a resonance')
RESOLVABLE_HZ_PER_RATE = 1.0  # ... and only where the resonance it implies lies below the sampling rate: a spring that
#                             rings faster than the samples come is not told from the integration's own error
UNRESOLVED_SPRING_SHARE = 1.0  # short of the hint, what a free spring term adds to J's uncertainty counts (J keeps
#                             the fit's value with its spring-term uncertainty): a 100 Hz coupling at ratio 10 biased
#                             J by 1.1-1.4 % with its term at -0.4 sigma
POSITION_MODEL_ERROR = 0.5  # half the position model's correction counts as uncertain where its load differs between
#                             the directions (backlash looks like a load that varies over the travel, and that model
#                             moved J by +3 % the wrong way) ...
ONE_WAY_SIGMA = 2.0  # ... by more than this many sigmas (an arm's gravity is the same both ways)
LOAD_HZ_MIN = 1.0  # a two-mass load's own resonance (against a held motor) is searched from here ...
LOAD_HZ_PER_RATE = 0.2  # ... up to this fraction of the sampling rate and LOAD_HZ_MAX, in steps of LOAD_HZ_STEP
LOAD_HZ_MAX = 60.0  # (stiffer couplings moved J by 0.4-1.4 %, within the uncertainty the other checks give)
LOAD_HZ_STEP = 1.15  # then twice finer around the best (a coarse grid first: the scan runs while the drive
#                           holds between moves, and the drive's watchdog waits for no fit)
SCAN_RATE = 400.0  # the scan integrates the load over samples at most this often (and every window's ends)
RESONANT_DAMPING = (0.015, 0.035, 0.08, 0.18)  # a coupling's damping ratios (seen from the load), DAMPING_STEP
DAMPING_STEP, MAX_RESONANT_DAMPING = 2.3, 0.3  # apart, refined up to MAX_RESONANT_DAMPING (beyond: a lag)
LAG_DAMPING = (0.5, 0.9)  # heavily damped 'couplings': a lag, which rigid loads show too (the speed's filter and
#                           the loop's transients): at 57600-115200 baud they left 0.2-0.7 of the rigid fit's residual
CANDIDATE_SHARE = 0.95  # the coarse grid's best resonance is refined where it leaves at most this share ...
RESONANCE_SHARE = 0.8  # ... and counts where it then leaves at most this share of the residual the rigid and the
#                           lag models leave (rigid loads: 1.2 and more; two-mass loads at 115200: 0.01-0.33, at
#                           57600 with torque read in whole % (IS620P): 0.7-0.8; backlash: 0.8 and more, refused) ...
RESONANCE_F = 30.0  # ... and the improvement is this many times what two free parameters get from noise
BIRGE_WIDEN = 1.5  # subsets that disagree more than this many times their uncertainties widen it (below,
#                           chance: chi2/dof of 2.25 over 2-3 subsets happens one time in ten on a rigid load)
BIRGE_REFUSE = 3.0  # refuse when the subsets disagree this many times beyond their uncertainties ...
GROSS_SPREAD = 0.08  # ... and their spread exceeds this fraction of J


@dataclass(frozen=True)
class Verdict:
    j: float
    j_std: float
    notes: tuple[str, ...]
    refuse: str = ""  # empty: usable (perhaps with a widened uncertainty)
    widened: str = ""  # why the uncertainty was widened (words for a refusal it causes), empty if not
    curable: bool = False  # the widening is one that stronger accelerations shrink (a remedy may be offered)
    residual: tuple[float, float] = (math.nan, math.nan)  # RMS per window of the model used's equation error and
    #                                                       of the torque integrals it explains (N*m*s)


def assess(fit: FitData) -> Verdict:
    """J and its uncertainty after the consistency checks, with the operator's words for what was found."""
    fit, why = clear_of_lost_motion(fit)
    lost = len(why)  # lost motion weighs less in a stronger motion: a refusal for it alone is curable
    notes: list[str] = []
    j, j_std, resid = float(fit.theta[0]), fit.j_std, fit.y - fit.x @ fit.theta
    widened = ""
    x = fit.x
    position = _position_model(fit)
    if position is not None:
        x = np.column_stack([x, position[0]])
        why.append(
            f"load varies over the travel (load torque changes by {position[1]:.0f} % of rated torque: an "
            "arm or a gravity axis on a gear?)"
        )
        j, j_std, resid = _take(fit, x, (j, j_std, resid), POSITION_MODEL_ERROR if position[2] else 0.0)
    mass = _two_mass(fit, x)
    spring = None if mass is not None else _compliance_model(fit, x, j, j_std)
    if mass is not None:
        why.append(f"resonance near {mass.hz:.0f} Hz: the load follows the motor through a compliant coupling")
        # The fit's own uncertainty misses how far the two-mass model is from the machine: a third of the change
        # it makes counts (20 Hz couplings at 115200 baud: 0.04-0.3 of a 4-31 % change left). The load's speed is
        # the motor's low-passed, its noise mostly filtered out: no errors-in-variables correction.
        j, j_std, resid = _take(
            replace(fit, y=mass.y, eiv=np.zeros_like(fit.eiv)), mass.x, (j, j_std, resid), 1 / MODEL_ERROR_DIVISOR
        )
    elif spring is not None and spring.strong:
        why.append(
            f"resonance or torque ripple near {spring.hz:.0f} Hz: the load follows the motor through a "
            "compliant coupling (or a long shaft, cogging)"
        )
        # The quasi-static spring term is approximate: a third of its correction counts as uncertain (a 20 Hz
        # coupling's correction left 2-5 % of a 7-28 % bias).
        j, j_std, resid = _take(fit, np.column_stack([x, spring.col]), (j, j_std, resid), 1 / MODEL_ERROR_DIVISOR)
    elif spring is not None and spring.z < -COMPLIANCE_HINT_SIGMA and spring.hz < RESOLVABLE_HZ_PER_RATE * _rate(fit):
        # A hint of a spring (a stiff coupling, 50-100 Hz): the rigid answer stands, uncertain by what the spring
        # term would change.
        hinted = _take(fit, np.column_stack([x, spring.col]), (j, j_std, resid), 0.0)
        if j_std <= fit.max_rel * abs(j):  # else too uncertain anyway: the hint is not why
            widened = f"perhaps a resonance near {spring.hz:.0f} Hz (a compliant coupling)"
        j_std = math.hypot(j_std, hinted[0] - j)
    elif spring is not None:
        # No evidence either way: at slow sampling the spring term cannot tell a stiff coupling from a rigid load
        # (and on rigid loads it picks up the integration's own error near torque steps), so the part of J's
        # uncertainty that a spring could add counts, without blaming one.
        j_std = math.hypot(j_std, UNRESOLVED_SPRING_SHARE * spring.unresolved)
    if why:
        notes.append(f"off-model: {'; '.join(why)}; inertia fitted with a model of it")
    fitted = (float(np.sqrt(np.mean(resid**2))), float(np.sqrt(np.mean(fit.y**2))))
    windows = Windows(fit.t, fit.w, fit.position, fit.starts, fit.ends, float(fit.eiv[0]), torque_step(fit.torque))
    birge, spread, name = worst_subsets(windows, fit.x[:, 0], j, j_std, resid)
    if birge > BIRGE_WIDEN:
        j_std *= birge
        text = f"inertia differs {name} by {100 * spread:.0f} % ({birge:.1f}x its uncertainty)"
        if birge > BIRGE_REFUSE and spread > GROSS_SPREAD:
            return Verdict(j, j_std, tuple(notes), refuse="; ".join([*why, f"{text}: {cause(name)}"]), residual=fitted)
        if not points_off_model(name, birge, spread):
            words, causes = unblamed(name)
            notes.append(f"uncertainty widened {birge:.1f}x: J differs {name} by {100 * spread:.0f} %, {words}")
            return Verdict(
                j,
                j_std,
                tuple(notes),
                widened="; ".join([*why, f"{text}: {causes}" if causes else text]),
                curable=len(why) == lost,
                residual=fitted,
            )
        notes.append(f"off-model: {text}; uncertainty widened to the spread ({cause(name)})")
        return Verdict(j, j_std, tuple(notes), widened="; ".join([*why, f"{text}; {cause(name)}"]), residual=fitted)
    return Verdict(
        j,
        j_std,
        tuple(notes),
        widened="; ".join([*why, widened] if widened else why),
        curable=len(why) == lost and not widened,
        residual=fitted,
    )


def _take(
    fit: FitData, x: np.ndarray, before: tuple[float, float, np.ndarray], model_error: float
) -> tuple[float, float, np.ndarray]:
    """(J, sigma, residual) of the extended fit; sigma grows by model_error times the correction to J."""
    found = refit(fit, x)
    if found is None:
        return before
    j = float(found[0][0])
    return j, math.hypot(max(float(found[1][0]), before[1]), model_error * (j - before[0])), found[2]


def _position_columns(fit: FitData) -> list[np.ndarray]:
    """Window integrals of the position (scaled to -1..1 over the travel) and its square."""
    pos = fit.position
    lo, hi = float(np.min(pos)), float(np.max(pos))
    u = (pos - 0.5 * (lo + hi)) / (0.5 * (hi - lo)) if hi > lo else np.zeros_like(pos)
    cols = []
    for p in (u, u * u):
        cum = cumulative_hermite(fit.t, p, fit.kink)
        cols.append(cum[fit.ends] - cum[fit.starts])
    return cols


def _position_model(fit: FitData) -> tuple[np.ndarray, float, bool] | None:
    """(the two position columns, the load's change over the travel in % of rated, whether it differs between the
    directions) when the load torque varies significantly with position, else None."""
    cols = _position_columns(fit)
    if not np.any(cols[0]):
        return None
    found = refit(fit, np.column_stack([fit.x, *cols]))
    if found is None:
        return None
    theta, std, _resid = found
    a1, a2 = theta[-2], theta[-1]
    significant = abs(a1) > POSITION_SIGMA * std[-2] or abs(a2) > POSITION_SIGMA * std[-1]
    grid = np.linspace(-1.0, 1.0, 21)
    change_pct = float(np.ptp(a1 * grid + a2 * grid * grid)) / fit.rated_nm * 100
    if not significant or change_pct < POSITION_MIN_PCT or not math.isfinite(std[0]):
        return None
    return np.column_stack(cols), change_pct, _one_way(fit, cols)


def _one_way(fit: FitData, cols: list[np.ndarray]) -> bool:
    """Whether the position dependence differs between forward and reverse moves: gravity on an arm is the same
    function of the position both ways, lost motion at the reversals (backlash) is not."""
    sgn = np.sign(fit.w[fit.starts])
    found = refit(fit, np.column_stack([fit.x, *cols, *(c * sgn for c in cols)]))
    if found is None:
        return True
    theta, std = found[0], found[1]
    return bool(np.any(np.abs(theta[-2:]) > ONE_WAY_SIGMA * std[-2:]))


@dataclass(frozen=True)
class _Spring:
    col: np.ndarray  # the compliance column (one per window)
    hz: float  # the resonance it implies
    z: float  # its coefficient in sigmas (negative: the sign a spring gives)
    strong: bool  # significant and moving J
    unresolved: float  # how much a free spring term adds to J's uncertainty (in quadrature)


def _compliance_model(fit: FitData, x: np.ndarray, j_before: float, j_std: float) -> _Spring | None:
    """The spring term when the motor runs ahead of or behind its load as through a spring (the coefficient has
    a spring's sign at all), else None. Strong: beyond COMPLIANCE_SIGMA and moving J.

    Through a spring k the load's speed differs from the motor's by the deflection's rate, about
    (J_load / J) * T' / k while the motion is slow against the resonance; the momentum balance over a window
    then gains the term -J_load^2 / (J k) * (T'(end) - T'(start)) = -(ratio / omega_r^2) * delta T'."""
    slope = _torque_slope(fit)
    col = slope[fit.ends] - slope[fit.starts]
    found = refit(fit, np.column_stack([x, col]))
    if found is None:
        return None
    theta, std, _resid = found
    b, j = float(theta[-1]), float(theta[0])
    ratio = j / fit.jm - 1.0
    if not (b < 0 and std[-1] > 0 and ratio > MIN_COMPLIANT_RATIO and math.isfinite(std[0])):
        return None
    z = b / float(std[-1])
    base = refit(fit, x)
    unresolved = math.sqrt(max(0.0, float(std[0]) ** 2 - float(base[1][0]) ** 2)) if base is not None else 0.0
    strong = z < -COMPLIANCE_SIGMA and abs(j - j_before) >= max(2 * j_std, COMPLIANCE_MIN_SHIFT * abs(j))
    return _Spring(col[:, None], math.sqrt(ratio / -b) / (2 * math.pi), z, strong, unresolved)


@dataclass(frozen=True)
class _TwoMass:
    hz: float  # the motor-side resonance (torque to motor speed)
    x: np.ndarray  # the regression with the load's speed change in place of the motor's
    y: np.ndarray  # the torque integrals less what turns the motor alone (Jm times the deflection's rate)


def _two_mass(fit: FitData, x: np.ndarray) -> _TwoMass | None:
    """The two-mass model where the motor speed carries a resolvable resonance of its load, else None.

    Through a spring and a damper the load's speed wL is the motor's w through a second-order low-pass at the load's
    own resonance fa; with the motor's inertia Jm known, the momentum balance over a window is
    J * delta wL = int T - Jm * (delta w - delta wL) - friction. The rigid fit absorbs the missing deflection rate
    as inertia (a 20 Hz coupling at ratio 2 and 115200 baud: +7 %, with a quasi-static spring term at 2 sigmas).
    fa and the damping are searched on a grid; heavily damped 'couplings' (a lag) are the reference it must beat."""
    rate, ratio = _rate(fit), float(fit.theta[0]) / fit.jm - 1.0
    top = min(LOAD_HZ_PER_RATE * rate, LOAD_HZ_MAX)
    if ratio <= MIN_COMPLIANT_RATIO or top <= LOAD_HZ_MIN * LOAD_HZ_STEP:
        return None
    hz = np.exp(np.arange(math.log(LOAD_HZ_MIN), math.log(top), math.log(LOAD_HZ_STEP)))
    grid_hz, grid_z = (a.ravel() for a in np.meshgrid(hz, RESONANT_DAMPING + LAG_DAMPING, indexing="ij"))
    j, rss = _follower_fits(fit, x, grid_hz, grid_z)
    rss0 = float(projected_fits(fit.x[:, :1], fit.y[:, None], x[:, 1:])[1][0])  # the rigid fit's
    resonant = grid_z < min(LAG_DAMPING)
    b = int(np.flatnonzero(resonant)[np.argmin(rss[resonant])])
    reference = min(rss0, float(np.min(rss[~resonant])))
    if rss[b] > CANDIDATE_SHARE * reference:
        return None
    best = (float(grid_hz[b]), float(grid_z[b]), float(j[b]), float(rss[b]))
    for spread_hz, spread_z in ((LOAD_HZ_STEP, DAMPING_STEP), (LOAD_HZ_STEP ** (1 / 3), DAMPING_STEP ** (1 / 3))):
        near_hz, near_z = (
            a.ravel()
            for a in np.meshgrid(
                best[0] * spread_hz ** np.linspace(-1, 1, 7),
                np.minimum(best[1] * spread_z ** np.linspace(-1, 1, 7), MAX_RESONANT_DAMPING),
                indexing="ij",
            )
        )
        j, rss = _follower_fits(fit, x, near_hz, near_z)
        b = int(np.argmin(rss))
        if rss[b] < best[3]:
            best = (float(near_hz[b]), float(near_z[b]), float(j[b]), float(rss[b]))
    dof = max(1, x.shape[0] - x.shape[1] - 2)
    if not (
        best[3] <= RESONANCE_SHARE * reference
        and (reference - best[3]) / 2 > RESONANCE_F * best[3] / dof
        and best[2] > 0
    ):
        return None
    dwl = _window_changes(fit, np.array(best[:1]), np.array(best[1:2]))[:, 0]
    y = fit.y - fit.jm * (fit.x[:, 0] - dwl)
    return _TwoMass(best[0] * math.sqrt(best[2] / fit.jm), np.column_stack([dwl, x[:, 1:]]), y)


def _follower_fits(fit: FitData, x: np.ndarray, hz: np.ndarray, damping: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(J, residual sum of squares) of the two-mass model at each (hz, damping) of the load (plain least squares: a
    ranking, the chosen model is refitted)."""
    dwl = _window_changes(fit, hz, damping)
    y = fit.y[:, None] - fit.jm * (fit.x[:, :1] - dwl)
    return projected_fits(dwl, y, x[:, 1:])


def _window_changes(fit: FitData, hz: np.ndarray, damping: np.ndarray) -> np.ndarray:
    """The load's speed change over each window (rows) for each (hz, damping) (columns)."""
    return follower_changes(fit.t, fit.w, fit.starts, fit.ends, hz, damping, SCAN_RATE)


def _rate(fit: FitData) -> float:
    """Samples per second (the median interval's)."""
    return float(1.0 / np.median(np.diff(fit.t))) if fit.t.size > 1 else 0.0


def _torque_slope(fit: FitData) -> np.ndarray:
    """dT/dt at each sample (central differences on the uneven times). Across a torque step too: the slope there
    is what the coupling's deflection follows (one-sided slopes at the steps caught only a third of the bias)."""
    if fit.torque.size < 3:
        return np.zeros_like(fit.torque)
    return np.gradient(fit.torque, fit.t)


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
