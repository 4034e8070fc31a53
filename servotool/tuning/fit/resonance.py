"""Model check: a resonance. Where the load follows the motor through a compliant coupling, the rigid fit takes the
deflection's rate for inertia; this check fits a model of the coupling and takes J from it.

Where the sampling resolves the load's own resonance, the two-mass model (the load's speed the motor's through a
spring and a damper, the motor's inertia known) is fitted over a grid of resonance and damping; it counts where a
lightly damped coupling explains the data far better than the rigid load and a heavily damped one (a lag, which
rigid loads show too). Otherwise a quasi-static spring term (the deflection's rate follows the torque's rate of
change) is tried, with what the torque reading's noise alone gives it taken out (the term reads the torque samples
its window's integral holds): strong, with its resonance below the sampling rate, J is taken from it; a hint of it
(beyond two sigmas) below the sampling rate, or a strong one above it, keeps the rigid J and widens its uncertainty
by what the term would change, unnamed; short of that it cannot tell a stiff coupling from the integration's own
error near torque steps, so its share of J's uncertainty counts, unnamed, for couplings up to the softest one the
two-mass scan leaves unsearched. A resonance is named by its frequency only below the log's Nyquist limit.
A fitted model's correction is uncertain by a third of its size: the models are approximate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from servotool.tuning.fit import lost_motion
from servotool.tuning.fit.estimate import RateBound
from servotool.tuning.fit.regression import FitData, projected_fits, refit
from servotool.tuning.fit.signals import cumulative_hermite
from servotool.tuning.fit.verdict import Cause, Verdict, take

MODEL_ERROR_DIVISOR = 3.0  # a correction by a fitted coupling model counts as uncertain by a third of its size
COVERED_SIGMA = 3.0  # where lost motion would explain the data as well, its J lies within this many sigmas
MIN_COMPLIANT_RATIO = 0.3  # below this load ratio there is too little load behind a coupling to matter
COMPLIANCE_SIGMA = 4.0  # a spring term counts when beyond this many sigmas ...
COMPLIANCE_MIN_SHIFT = 0.01  # ... and moves J by more than this fraction (and 2 sigma)
COMPLIANCE_HINT_SIGMA = 2.0  # beyond this many it widens the uncertainty by what it would change J (one-sided 2 sigma)
RESOLVABLE_HZ_PER_RATE = 1.0  # both where the resonance it implies lies below the sampling rate: a spring that rings
#                               faster than the samples come is not told from the integration's own error (or the
#                               speed reading's lag), which a long log makes as significant as any spring
NYQUIST_SHARE = 0.5  # a resonance is named by its frequency only below this share of the sampling rate
STENCIL_REACH = 6  # a window's torque integral and slopes reach at most this many samples beyond its span
UNRESOLVED_SPRING_SHARE = 1.0  # short of a hint, this share of what a free spring term adds to J's uncertainty counts
#                                (its 1-sigma range cut at the softest coupling the two-mass scan does not search)
SPRING_WITHIN_SIGMAS = 1.0  # a term of the other sign leaves a spring plausible up to this many sigmas: its share
#                             tapers to none there, so that an insignificant term's sign does not decide alone
LOAD_HZ_MIN = 1.0  # a two-mass load's own resonance (against a held motor) is searched from here ...
LOAD_HZ_PER_RATE = 0.2  # ... up to this fraction of the sampling rate and LOAD_HZ_MAX, in steps of LOAD_HZ_STEP
LOAD_HZ_MAX = 60.0  # (stiffer couplings move J by less than the other checks' uncertainty)
LOAD_HZ_STEP = 1.15  # then twice finer around the best: a coarse grid first, since the scan runs while the drive
#                      holds between moves and its watchdog waits for no fit
SCAN_RATE = 400.0  # the scan integrates the load over samples at most this often (and every window's ends)
RESONANT_DAMPING = (0.015, 0.035, 0.08, 0.18)  # a coupling's damping ratios (seen from the load), DAMPING_STEP
DAMPING_STEP, MAX_RESONANT_DAMPING = 2.3, 0.3  # apart, refined up to MAX_RESONANT_DAMPING (beyond: a lag)
LAG_DAMPING = (0.5, 0.9)  # heavily damped 'couplings': a lag, which rigid loads show too (the speed's filter, the
#                           loop's transients)
CANDIDATE_SHARE = 0.95  # the coarse grid's best resonance is refined where it leaves at most this share ...
RESONANCE_SHARE = 0.8  # ... and counts where it then leaves at most this share of the residual the rigid and the
#                        lag models leave ...
RESONANCE_F = 30.0  # ... and the improvement is this many times what two free parameters get from noise
FOLLOWER_BLOCK_DECAY = 30.0  # follower_speed's blocks: the heaviest-damped mode decays by at most exp(-this) in one


def check(v: Verdict) -> Verdict:
    """J from the two-mass model where it counts, else from a strong spring term; a hint of a spring widens the
    uncertainty, no evidence adds the spring's share. A resonance is named by its frequency only below the Nyquist
    limit of the log's own sampling rate."""
    fit, x = v.fit, v.x
    rate = _rate(fit)
    mass = _two_mass(fit, x)
    if mass is not None:
        # The load's speed is the motor's low-passed, its noise mostly filtered out: no errors-in-variables correction.
        j, j_std, resid = take(
            replace(fit, y=mass.y, eiv=np.zeros_like(fit.eiv)), mass.x, (v.j, v.j_std, v.resid), 1 / MODEL_ERROR_DIVISOR
        )
        return replace(
            v, j=j, j_std=j_std, resid=resid, fitted=(*v.fitted, Cause(_mass_words(mass, rate), curable=False))
        )
    spring = _compliance_model(fit, x, v.j, v.j_std)
    if spring is None:
        return v
    with_spring = np.column_stack([x, spring.col])
    resolved = spring.hz < RESOLVABLE_HZ_PER_RATE * rate
    if spring.strong and resolved:
        j, j_std, resid = take(fit, with_spring, (v.j, v.j_std, v.resid), 1 / MODEL_ERROR_DIVISOR, spring.shared)
        cause = _spring_words(spring.hz, rate)
        lost = _lost_motion_reading(v, j)
        if lost is None:
            return replace(v, j=j, j_std=j_std, resid=resid, fitted=(*v.fitted, Cause(cause, curable=False)))
        # Either may be right: the stated 3 sigma covers the other's J. Lost motion weighs less in a stronger
        # motion (and the ambiguity with it), so a longer travel may cure it.
        j_std = math.hypot(j_std, abs(lost[0] - j) / COVERED_SIGMA)
        return replace(v, j=j, j_std=j_std, resid=resid, fitted=(*v.fitted, Cause(f"{cause}, {lost[1]}", curable=True)))
    if spring.z < -COMPLIANCE_HINT_SIGMA and (resolved or spring.strong):
        # Unnamed: a hint is what a rigid load's noise shows now and then; a longer log tells them apart. A strong
        # term whose resonance the sampling does not resolve may be the integration's own error as much as a
        # coupling (DSX7E 19200, load 37 behind a 60 Hz coupling: z -7, 'near 68 Hz' at 65 samples/s, J 6 % high
        # with only the share below counted): what it would change counts too. A hint above the sampling rate does
        # not (a rigid SD25 load at 35 samples/s shows z -3 'near 55 Hz' run after run).
        hinted = take(fit, with_spring, (v.j, v.j_std, v.resid), 0.0, spring.shared)
        return replace(v, j_std=math.hypot(v.j_std, hinted[0] - v.j))
    share = UNRESOLVED_SPRING_SHARE * spring.unresolved
    # cut at the softest unscanned coupling, the share is a ratio of the regressors that stronger moves keep (RateBound)
    bound = RateBound(share / v.j, spring.release, _scan_top(rate), rate) if spring.release > 1 and v.j > 0 else None
    return replace(v, j_std=math.hypot(v.j_std, share), rate_bound=bound)


def _mass_words(mass: _TwoMass, rate: float) -> str:
    """The words for a two-mass load: the motor side's resonance where the sampling resolves it (below the Nyquist
    limit), else the load's own, which the scan found below it."""
    coupling = "the load follows the motor through a compliant coupling"
    if mass.hz < NYQUIST_SHARE * rate:
        return f"resonance near {mass.hz:.0f} Hz: {coupling}"
    return (
        f"{coupling}, the load's own resonance near {mass.load_hz:.0f} Hz (the motor side's lies above the "
        f"{NYQUIST_SHARE * rate:.0f} Hz that {rate:.0f} samples/s resolve)"
    )


def _spring_words(hz: float, rate: float) -> str:
    """The words for a spring term that counts: its resonance named where the sampling resolves it (below the
    Nyquist limit, half the sampling rate), else only that it lies beyond."""
    coupling = "the load follows the motor through a compliant coupling (or a long shaft, cogging)"
    if hz < NYQUIST_SHARE * rate:
        return f"resonance or torque ripple near {hz:.0f} Hz: {coupling}"
    return f"{coupling}, its resonance above the {NYQUIST_SHARE * rate:.0f} Hz that {rate:.0f} samples/s resolve"


@dataclass(frozen=True)
class _Spring:
    col: np.ndarray  # the compliance column (one per window)
    shared: np.ndarray  # per window and column of the regression with it: its noise times the torque integral's
    hz: float  # the resonance it implies
    z: float  # its coefficient in sigmas (negative: the sign a spring gives), clear of what the shared noise gives
    strong: bool  # significant and moving J
    unresolved: float  # how much a free spring term adds to J's uncertainty (in quadrature)
    release: float  # how many times the information must grow before the cut at the softest unscanned coupling goes


def _compliance_model(fit: FitData, x: np.ndarray, j_before: float, j_std: float) -> _Spring | None:
    """The spring term when the motor may run ahead of or behind its load as through a spring (the coefficient has
    a spring's sign, or the other within SPRING_WITHIN_SIGMAS: its resonance then infinite), else None. Strong:
    beyond COMPLIANCE_SIGMA and moving J.

    Through a spring k the load's speed differs from the motor's by the deflection's rate, about
    (J_load / J) * T' / k while the motion is slow against the resonance; the momentum balance over a window
    then gains the term -J_load^2 / (J k) * (T'(end) - T'(start)) = -(ratio / omega_r^2) * delta T'.
    The torque's slope at a window's ends is read from the samples next to them, which the window's torque integral
    holds too: their noise alone gives the term a spring's sign (a rigid load at 1 % noise named a 17 Hz
    resonance at 6 sigma), and its expected share is taken out of the fit (_shared_noise)."""
    slope = _torque_slope(fit.t, fit.torque)
    col = slope[fit.ends] - slope[fit.starts]
    shared = np.zeros((col.size, x.shape[1] + 1))
    shared[:, -1] = _shared_noise(fit)
    found = refit(fit, np.column_stack([x, col]), shared)
    if found is None:
        return None
    theta, std, _resid = found
    b, j = float(theta[-1]), float(theta[0])
    ratio = j / fit.jm - 1.0
    if not (std[-1] > 0 and ratio > MIN_COMPLIANT_RATIO and math.isfinite(std[0])):
        return None
    z = b / float(std[-1])
    if z >= SPRING_WITHIN_SIGMAS:
        return None
    base = refit(fit, x)
    unresolved = math.sqrt(max(0.0, float(std[0]) ** 2 - float(base[1][0]) ** 2)) if base is not None else 0.0
    softest = _softest_unscanned(fit, ratio)
    release = float(std[-1]) / softest if softest < float(std[-1]) else 1.0
    unresolved /= release
    unresolved *= min(1.0, 1.0 - z / SPRING_WITHIN_SIGMAS)
    strong = z < -COMPLIANCE_SIGMA and abs(j - j_before) >= max(2 * j_std, COMPLIANCE_MIN_SHIFT * abs(j))
    hz = math.sqrt(ratio / -b) / (2 * math.pi) if b < 0 else math.inf
    return _Spring(col[:, None], shared, hz, z, strong, unresolved, release)


def _softest_unscanned(fit: FitData, ratio: float) -> float:
    """The largest spring coefficient (-b) of a coupling the two-mass scan would not have searched: one whose load
    resonates above the scan's top (b = -ratio / omega_r^2, omega_r^2 = omega_load^2 (1 + ratio)); infinite where
    the scan does not run. A free spring term's share of J's uncertainty counts only up to it: its 1-sigma range
    can reach couplings so soft that the whole load would swing at a few Hz, which the scan sees."""
    top = _scan_top(_rate(fit))
    if top <= LOAD_HZ_MIN * LOAD_HZ_STEP:
        return math.inf
    return ratio / ((2 * math.pi * top) ** 2 * (1.0 + ratio))


def _scan_top(rate: float) -> float:
    """The highest load resonance the two-mass scan searches at this sampling rate."""
    return min(LOAD_HZ_PER_RATE * rate, LOAD_HZ_MAX)


def _shared_noise(fit: FitData) -> np.ndarray:
    """Per window, the expected product of the spring column's noise with its torque integral's, for a torque
    reading with white noise of fit.torque_noise_pct: both are linear in the torque samples, and a comb of unit
    impulses further apart than a window and its stencils reach hits each window's samples at most once, so the
    products of the two responses, summed over the combs, are the sums over each window's samples exactly."""
    n = fit.t.size
    spacing = int(np.max(fit.ends - fit.starts)) + STENCIL_REACH
    total = np.zeros(fit.starts.size)
    for first in range(min(spacing, n)):
        probe = np.zeros(n)
        probe[first::spacing] = 1.0
        integral = cumulative_hermite(fit.t, probe, fit.kink, fit.cut)
        slope = _torque_slope(fit.t, probe)
        total += (integral[fit.ends] - integral[fit.starts]) * (slope[fit.ends] - slope[fit.starts])
    return (fit.torque_noise_pct / 100.0 * fit.rated_nm) ** 2 * total


def _lost_motion_reading(v: Verdict, j_spring: float) -> tuple[float, str] | None:
    """(J of the windows clear of possible lost motion, words) where they contradict the spring's J, else None.

    Backlash is a coupling with no stiffness inside its gap: while the motor crosses it the load lags as behind a
    soft spring, and the spring term takes J a few % low (0.1 rad of backlash at ratio 2 and 4 rev reads as a
    15-17 Hz spring: accepted 3-4 sigma low in 8 of 12 runs). On the windows clear of lost motion
    (fit.lost_motion.clear) a coupling's J mostly stays the rigid fit's or moves toward the spring's, lost motion's
    the other way, beyond the rigid J. A real coupling does that too at times (30 Hz at ratio 2 and 4 rev, 4 of 6
    runs), and one run does not tell them apart: where it happens both are named."""
    if any(c.words.startswith(lost_motion.WORDS) for c in v.fitted):  # the windows are clear of it already
        return None
    found = lost_motion.clear(v.fit)
    if found is None:
        return None
    rigid = refit(found.fit, v.x[found.keep])
    if rigid is None:
        return None
    j_clear = float(rigid[0][0])
    if (j_clear - v.j) * (v.j - j_spring) <= 0:
        return None
    return j_clear, (
        f"or {lost_motion.WORDS} where the torque reverses: the {found.fit.starts.size} of {v.fit.starts.size} "
        f"windows clear of it put J {100 * abs(j_clear / j_spring - 1):.0f} % the other way"
    )


@dataclass(frozen=True)
class _TwoMass:
    hz: float  # the motor-side resonance (torque to motor speed)
    load_hz: float  # the load's own resonance against a held motor (what the scan resolves)
    x: np.ndarray  # the regression with the load's speed change in place of the motor's
    y: np.ndarray  # the torque integrals less what turns the motor alone (Jm times the deflection's rate)


def _two_mass(fit: FitData, x: np.ndarray) -> _TwoMass | None:
    """The two-mass model where the motor speed carries a resolvable resonance of its load, else None.

    Through a spring and a damper the load's speed wL is the motor's w through a second-order low-pass at the load's
    own resonance fa; with the motor's inertia Jm known, the momentum balance over a window is
    J * delta wL = int T - Jm * (delta w - delta wL) - friction. The rigid fit absorbs the missing deflection rate
    as inertia.
    fa and the damping are searched on a grid; heavily damped 'couplings' (a lag) are the reference it must beat."""
    rate, ratio = _rate(fit), float(fit.theta[0]) / fit.jm - 1.0
    top = _scan_top(rate)
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
    return _TwoMass(best[0] * math.sqrt(best[2] / fit.jm), best[0], np.column_stack([dwl, x[:, 1:]]), y)


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


def _torque_slope(t: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """dT/dt at each sample (central differences on the uneven times). Across a torque step too: the slope there
    is what the coupling's deflection follows."""
    if torque.size < 3:
        return np.zeros_like(torque)
    return np.gradient(torque, t)


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
