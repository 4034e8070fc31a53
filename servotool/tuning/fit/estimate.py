"""The inertia fit's contract: the settings it runs with, the estimate it returns, and the record its stages fill.

Every stage of the pipeline (fit.pipeline) writes what it found into one Partial, and stops the fit by raising
Refused: a refusal then reports everything known up to the stage that refused, which is what tells the operator
whether more motion would help.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


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
    """Refuse when the 1-sigma uncertainty of J_total exceeds this fraction of J_total (the ratio's may be at most
    this times 1 + ratio). Gain tuning tolerates several times this error, so the limit leaves margin."""
    min_excitation: float = 10.0
    """Refuse when the speed changes within windows (RMS) are less than this many times the speed noise of a
    window (sqrt(2) * noise). Plain least squares would bias J low by about 1/excitation^2; the fit removes that
    bias with the estimated noise, so this bounds what an error in that estimate can cost."""
    max_rel_residual: float = 0.3
    """Refuse when RMS(equation error) / RMS(integrated torque) exceeds this: the model does not fit (backlash,
    compliance, a torque reading that is not the shaft torque)."""
    saturation_fraction: float = 0.98
    """A torque sample with |T| >= this * torque limit counts as saturated."""
    max_saturated_samples: int = 0
    """Refuse when more samples than this are saturated (a saturated drive no longer follows the test motion)."""
    kink_sigma: float = 5.0
    """A torque sample further than this many noise sigmas off the line through its neighbours marks a torque step
    (start/end of an acceleration: a kink in speed), and the intervals on both sides are left out; so is a speed
    sample this far off, or at a slow line (signals.CORNERS_BETWEEN_S) an interval across which the speed's slope
    changes this far (signals.corner_cuts). No interpolant can integrate a step that falls somewhere between two
    slow samples, and its error is correlated with the window's speed change, which biases J low. Speed shows the
    kink even when the torque step is buried in torque noise."""
    torque_noise_floor_pct: float = 0.05
    """Floor of the estimated torque noise (% of rated) used for the kink test, so clean data is not all kinks."""
    torque_noise_pct: float | None = None
    """The torque reading's noise (1 sigma, % of rated) apart from its steps, as read with the axis at rest. None:
    estimated from the log (signals.torque_noise_pct), which at a slow line takes the loop's swing between samples
    for noise too. The spring term of the model checks (fit.resonance) shares torque samples with the torque
    integrals: this noise alone gives it a spring's sign."""
    zero_band_rpm: float | None = None
    """Samples with |speed| below this are left out. None: max(2 % of the peak speed, 3 * speed noise)."""
    speed_noise_rpm: float | None = None
    """Speed measurement noise (1 sigma). None: estimated from the log (floored at 0.1 rpm, and at the speed
    reading's own step: speed_step_rpm)."""
    speed_step_rpm: float | None = None
    """The speed reading's resolution (rpm), as the drive's register states it. None: found from the log (the grid
    its readings lie on, 0 if none). Its rounding is noise in every speed change, which a log that moves between
    steps slowly hides from the noise estimate (signals.speed_noise_rpm)."""
    speed_between_reads: bool = False
    """The speed was read apart from the torque and interpolated onto the torque's times (SD25): its noise is then
    shared between neighbouring samples, which the errors-in-variables correction does not model. The fit keeps
    what it was measured with for such logs (bench/inertia_accuracy.py, SD25 9600): the noise from every sample
    and kinks at speed samples off the line, however slow (signals.CORNERS_BETWEEN_S: SD25's errors went low)."""
    torque_step_pct: float | None = None
    """The torque reading's resolution (% of rated), as the drive's register states it. None: found from the log
    (signals.reading_step: the grid its readings lie on, 0 if none)."""
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
class MoveEstimate:
    """The load ratio one move (a run of one speed sign) gives on its own: J from its windows, with friction and load
    torque held at the whole fit's (so the moves can be compared with each other and with the whole), and its own
    uncertainty, from the scatter of its own windows about it. A move that gives no J of its own (too little speed
    change, or none a real load can have) says why and carries NaN."""

    direction: int  # +1 forward, -1 reverse
    load_ratio: float
    ratio_std: float  # 1 sigma from this move's own windows
    windows: int
    peak_rpm: float = math.nan  # the highest speed its windows reached
    why: str = ""  # why it gives no ratio of its own; empty when it does

    @property
    def fitted(self) -> bool:
        return not self.why


@dataclass(frozen=True)
class FittedWindow:
    """One window the estimate stands on: its span (s) and its average torque, measured and as the model used
    explains it (N*m); only where the model was fitted."""

    t0: float
    t1: float
    measured_nm: float
    model_nm: float


@dataclass(frozen=True)
class RateBound:
    """A share of J's uncertainty that a model check adds, unnamed, for what the log's sampling rate leaves open
    (fit.resonance: a coupling stiffer than the two-mass scan searches, a top the rate sets). In windows of the same
    length it is what J would move by for the softest such coupling, a ratio of the regressors that no amplitude and
    no number of moves changes, until the information grows `release` times; then it falls with it. So a refusal for
    it names no travel that leaves the windows as they are: only a faster line lowers it."""

    rel: float  # relative to J, added in quadrature
    release: float  # > 1: how many times the information must grow before it falls
    top_hz: float  # the stiffest load resonance the scan searches
    rate: float  # the log's samples/s

    def at(self, gain: float) -> float:
        """The share where moves in windows of the same length carry `gain` times this log's information (their
        acceleration times the root of their samples): as it is up to `release`, then falling with the gain."""
        return self.rel * min(1.0, self.release / gain) if gain > 0 else self.rel


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
    """Samples recognised as torque steps (kinks) and left out with their neighbouring intervals, and intervals
    holding a speed corner (left out alone)."""
    condition: float
    notes: tuple[str, ...] = field(default_factory=tuple)
    advice: str = ""
    """What would cure a refusal, in general terms; the caller that planned the motion may say it in its own."""
    shortfall: float = math.nan
    """How many times short of its limit a refusal that more excitation would cure fell (else NaN)."""
    moves: tuple[MoveEstimate, ...] = ()
    """Each move's own ratio, in the order run (none where the fit stopped before its checks)."""
    fitted_windows: tuple[FittedWindow, ...] = ()
    """The windows of the model the estimate stands on (none where the fit stopped before its checks)."""
    floor_rel: float = math.nan
    """The torque reading's step floor (fit.quantization) in j_std_kgm2, relative to J; NaN where none was added."""
    fit_std_kgm2: float = math.nan
    """J's uncertainty from the rigid fit alone (least squares, MA(1), jackknife), before the model checks widened
    it: what the line's budget (tuning.budget) models; NaN where the fit stopped before it."""
    rate_bound: RateBound | None = None
    """The share of j_std_kgm2 that the sampling rate, not the excitation, bounds (None: none)."""


class Refused(Exception):
    """The fit stops here; the message is the reason, in words for the operator, and `advice` what would cure it."""

    def __init__(self, reason: str, advice: str = "") -> None:
        super().__init__(reason)
        self.advice = advice


@dataclass
class Partial:
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
    moves: tuple[MoveEstimate, ...] = ()
    fitted_windows: tuple[FittedWindow, ...] = ()
    fit_std: float = math.nan
    floor_rel: float = math.nan
    rate_bound: RateBound | None = None

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
            moves=self.moves,
            fitted_windows=self.fitted_windows,
            fit_std_kgm2=self.fit_std,
            floor_rel=self.floor_rel,
            rate_bound=self.rate_bound,
        )
