"""Host-driven inertia identification: run the planned moves, sample speed and torque, estimate."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.model.roles import status_bit
from servotool.motion.keepalive import KeepAlive, keepalive_interval_s
from servotool.motion.moves import Mover
from servotool.motion.rest import band_of as rest_band
from servotool.motion.stop import MotionStop, StopReport
from servotool.ops.eeprom import ram_writes
from servotool.ops.params import write_one
from servotool.tuning import budget
from servotool.tuning.band_guard import BandGuard
from servotool.tuning.errors import IdentificationFailed, TravelExceeded, TravelNeeded
from servotool.tuning.fit import EstimatorSettings, InertiaEstimate, estimate_inertia
from servotool.tuning.fit.estimate import RateBound
from servotool.tuning.fit.signals import STALL_S, host_gaps, paused_within, stall
from servotool.tuning.planning import (
    COARSE_TORQUE_STEP_PCT,
    MIN_RAMP_S,
    PILOT_SHARE,
    MotionPlan,
    Remedy,
    dithered,
    remedy,
)
from servotool.tuning.preflight import FEATURE, RestCheck, active_alarm
from servotool.tuning.sampling import Sampler, Trace, TravelLimitReached
from servotool.tuning.stable_hold import StableHold, pilot_settings

__all__ = ["IdentificationRefused", "Identifier", "Result", "Trace"]


@dataclass
class Result:
    method: str
    old_ratio: float | None  # None: the profile maps no inertia-ratio parameter
    new_ratio: float
    estimate: InertiaEstimate | None
    trace: Trace
    plan: MotionPlan | None
    travel_used_rev: float | None
    time_used_s: float
    samples_per_s: float
    cycles: int = 0


class IdentificationRefused(IdentificationFailed):
    """The motion ran, but the estimate is not trustworthy; the result (with its trace) is attached."""

    def __init__(self, message: str, result: Result, remedy: Remedy | None = None) -> None:
        super().__init__(message)
        self.result = result
        self.remedy = remedy  # a longer travel that would likely succeed, where that is what fell short


class Identifier:
    """Runs the identification motion on one drive."""

    def __init__(self, drive: Drive, timing: Clock | None = None, keepalive_s: float | None = None) -> None:
        self.drive = drive
        self.p = drive.profile
        self.timing = timing or RealClock()
        self.keepalive_s = keepalive_s
        self.trace = Trace()  # filled while the motion runs; kept when it fails

    def current_ratio(self) -> float | None:
        """The drive's configured load ratio; None where the profile maps no inertia-ratio parameter."""
        entry = self.p.role("inertia_ratio")
        return self.p.load_ratio_from_param(_eng(self.drive, entry)) if entry is not None else None

    # ----- host method ---------------------------------------------------------------------------------------
    def run_host(
        self, plan: MotionPlan, progress: Callable[[str], None] | None = None, rest: RestCheck | None = None
    ) -> Result:
        """Pilot cycle, then the planned cycles; fit; raise IdentificationRefused when the fit is refused.

        The motion's own writes (speed, ramp) stay out of EEPROM where the drive has a switch."""
        with ram_writes(self.drive):
            return self._run_host(plan, progress, rest)

    def _run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None, rest: RestCheck | None) -> Result:
        p, d = self.p, self.drive
        mover = Mover(
            d, self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d), FEATURE, self.timing
        )
        limit_e = p.role("torque_limit_fwd")
        if plan.needs is not None:  # read once, before the motion was planned
            torque_limit = plan.needs.line.torque_limit_pct
        else:
            torque_limit = _eng(d, limit_e) if limit_e is not None else None
        old_ratio = self.current_ratio()
        estimate = trace_estimate(p, torque_limit, rest.torque_noise_pct if rest is not None else None)
        run = _HostRun(mover, self.timing, plan, estimate, torque_limit, old_ratio, progress, rest)
        self.trace = run.sampler.trace
        return run.run()

    # ----- drive method --------------------------------------------------------------------------------------
    def run_drive(self, timeout_s: float = 30.0, keep: bool = True) -> Result:
        """Trigger the drive's own identification, wait for it, read the inertia ratio it stored.

        The drive stores its result itself; keep=False (dry run) puts the previous value back afterwards.
        """
        p, d = self.p, self.drive
        ratio_e = p.need_role("inertia_ratio", FEATURE)
        old_raw = d.read_entries([ratio_e])[0].raw
        old = p.load_ratio_from_param(float(raw_to_eng(ratio_e, old_raw)))
        keepalive = KeepAlive(
            d, self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d), self.timing
        )
        t0 = self.timing.now()
        status = p.role("servo_status")
        ident_bit = status_bit(status, "identifying") if status is not None else None
        with MotionStop(_OwnIdentification(d, keepalive, self.timing)):  # however it ends: aborted, proven at rest
            d.trigger("inertia_id", FEATURE)
            while self.timing.now() - t0 < timeout_s:
                self.timing.sleep(min(0.1, keepalive.interval_s))
                keepalive.beat()
                if status is None or ident_bit is None:
                    continue
                if not d.read_entries([status])[0].raw >> ident_bit & 1:
                    break
            else:
                raise IdentificationFailed(f"the drive's identification did not finish within {timeout_s:g} s")
        active = active_alarm(d)
        if active:
            raise IdentificationFailed(f"the drive stopped its identification with alarm {active}")
        new_raw = d.read_entries([ratio_e])[0].raw
        new = p.load_ratio_from_param(float(raw_to_eng(ratio_e, new_raw)))
        if not keep and new_raw != old_raw:
            write_one(d, ratio_e, old_raw)
        return Result("drive", old, new, None, Trace(), None, None, self.timing.now() - t0, 0.0)


class _OwnIdentification:
    """The drive's own identification as the stop sequence sees it (motion/stop.py): its zero command aborts it."""

    def __init__(self, drive: Drive, keepalive: KeepAlive, clock: Clock) -> None:
        self.drive, self.keepalive, self.clock = drive, keepalive, clock

    def command_zero(self) -> float | None:
        self.drive.trigger("inertia_id", FEATURE, 0)
        return None

    def keep_alive(self) -> None:
        self.keepalive.beat()

    def start_protection(self, saved: dict[str, int]) -> None:
        pass  # the drive's own motion: nothing of servotool's to set on it

    def release(self) -> bool:
        self.keepalive.stop_heartbeat()
        return False  # nothing forced

    def leave(self) -> None:
        servo = self.drive.profile.role("servo_on")
        if servo is not None:
            self.drive.write_raw(servo, 0)

    def snapshot(self, need_ramp: bool) -> dict[str, int]:
        return {}  # the drive writes only its result, which the caller keeps or puts back

    def stop_wait_s(self) -> float:
        return 3.0

    def moving_rpm(self) -> float | None:
        return None  # the drive's own motion: its speed is not servotool's

    def starved(self) -> str:
        return ""  # the drive's own function runs the motion: no host-timed beat to miss

    def stopped(self, report: StopReport) -> None:
        pass


Estimate = Callable[[Trace, EstimatorSettings], InertiaEstimate]
"""A trace fitted as its drive's identification fits it, with the settings asked for (the pilot's or the final)."""


def trace_estimate(profile: Profile, torque_limit_pct: float | None, torque_noise_pct: float | None = None) -> Estimate:
    """How this drive's traces are fitted: windows up to about a fifth of a second at the trace's sampling rate (a
    fast link gives many samples a ramp), the torque and speed readings' steps as their registers state them, the
    torque reading's noise as the rest check read it (None: from the trace), saturation at the drive's torque
    limit."""
    motor = profile.motor
    assert motor is not None
    step_pct = profile.need_role("torque_feedback", FEATURE).scale
    step_rpm = profile.need_role("speed_feedback", FEATURE).scale

    def estimate(trace: Trace, settings: EstimatorSettings) -> InertiaEstimate:
        cfg = replace(
            settings,
            max_window_intervals=max(6, int(trace.rate() / 5)),
            torque_step_pct=step_pct,
            speed_step_rpm=step_rpm,
            torque_noise_pct=torque_noise_pct,
            speed_between_reads=trace.speed_between_reads,
        )
        t, speed, torque, position = trace.fitted()
        return estimate_inertia(
            t,
            speed,
            torque,
            position_rev=position,
            paused=trace.paused,
            rated_torque_nm=motor.rated_torque_nm,
            rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
            torque_limit_pct=torque_limit_pct,
            settings=cfg,
        )

    return estimate


def _eng(drive: Drive, entry: Entry) -> float:
    return float(raw_to_eng(entry, drive.read_entries([entry])[0].raw))


# The pilot's load for the travel it needs (tuning.budget): a fit of the pilot's weak moves that gives J however
# uncertain (its lower bound is what counts, and a noisy speed change biases J low, never high).
ROUGH = {"min_windows": 4, "min_excitation": 2.0, "max_rel_uncertainty": 1.0}
PILOT_EFFICIENCY_CAP = 4.0  # the most the pilot's own fit may scale the budget by (it is rough)
# A pilot names a travel only beyond this many times the travel allowed; closer, the motion goes on with the longest
# time budget and the fit decides: a rough pilot's need is no better than the one a whole run's refusal named (SDC
# 9600 draw seed 31, the motor alone: a refusal named 8 rev, and followed, the pilot stopped naming 10).
PILOT_SLACK = 1.5
# A travel limit reached after a gap between samples this many usual ones long (and STALL_S) is named as the host's
# stall: fewer than a fit's stall (fit.signals: 6, where the windows stop spanning it), since one gap late in a
# host-timed move's ramp is enough to let it run on.
STALL_INTERVALS = 4.0
TARGET_TOLERANCE = 0.1  # a host-timed move rests within this share of its travel of its target (_tolerance)
EXTEND_AIM = 0.85  # a time budget is extended to reach this share of the uncertainty limit (_extended)
CATCH_UP_RAMPS = 2.0  # a move short of its target runs on for at most this many ramps more
REST_RAMPS = 0.5  # the axis rests this many ramp times (at least two samples) between moves
STALL_RAMPS = 2.0  # a dithered ramp lasts at least this many of the longest gaps between samples
STEP_FLOOR_SHARE = 0.25  # a torque-step floor beyond this share of the limit lets the test speed use the drive's limit
LATE_NAMED = 0.05  # samples left out of the fit beyond this share: the host was late, named and given more time
LATE_EXTEND = 1.5  # a fit refused outright on a late host: its time budget grows by this factor squared at a time
SAME_PILOT = 1.05  # a plan's speed within this factor of its limit: a longer travel runs the same pilot (_remedy_line)


def torque_swing(speed: list[float], torque: list[float], step_pct: float) -> float:
    """A move's acceleration torque (% of rated): half the spread of its torque while it moves (above a fifth of its
    peak speed), where accelerating and braking torque differ by twice it and friction and gravity not at all; at
    least half the reading's step (a spread the reading does not show may be up to a step)."""
    moving = [q for v, q in zip(speed, torque, strict=False) if abs(v) > 0.2 * max(map(abs, speed), default=0.0)]
    spread = max(moving) - min(moving) if moving else 0.0
    return max(spread / 2.0, step_pct / 2.0)


def _load_shown(est: InertiaEstimate) -> float:
    """The load ratio a refused estimate shows, for planning the strongest motion a remedy may name: none below the
    motor alone, and the motor alone where it shows none."""
    return max(est.load_ratio, 0.0) if math.isfinite(est.load_ratio) else 0.0


def _relative_std(est: InertiaEstimate) -> float:
    """sigma(J) / J of an estimate; for a J below the rotor's that fit.conclude judged at the rotor's inertia (the
    least J a load gives: the torque reading's steps hid the acceleration), that judgement's; NaN for a J at or below
    zero otherwise. The scale a time extension and a remedy project from."""
    at_rotor = est.load_ratio < 0 and math.isfinite(est.floor_rel)
    if est.j_total_kgm2 > 0 and not at_rotor:
        return est.j_std_kgm2 / est.j_total_kgm2
    return est.shortfall * EstimatorSettings().max_rel_uncertainty


class _HostRun:
    """One host identification: the pilot, the planned cycles and the fit, on one Jogger and one Sampler."""

    def __init__(
        self,
        jogger: Mover,
        timing: Clock,
        plan: MotionPlan,
        estimate: Estimate,
        torque_limit: float | None,
        old_ratio: float | None,
        progress: Callable[[str], None] | None,
        rest: RestCheck | None,
    ) -> None:
        d = jogger.drive
        p = d.profile
        self.drive, self.jogger, self.timing, self.plan, self.progress = d, jogger, timing, plan, progress
        self.estimate, self.torque_limit, self.old_ratio = estimate, torque_limit, old_ratio
        jogger.protect_for(plan.speed_rpm, plan.travel_limit_rev)  # the drive's own, set with the settings
        self.jog_accel = p.need_role("jog_accel", FEATURE)
        self.ramp_rpm = p.ramp_rpm()  # the speed the drive's ramp time runs up to
        self.stop_band = rest_band(rest.speed_noise_rpm if rest is not None else 0.0)  # noise the rest check measured
        self.sampler = Sampler(d, self.timing, plan.travel_limit_rev, self._beat)
        # A torque read in whole percent: its step error would repeat in every move of the same acceleration.
        self.torque_step_pct = p.need_role("torque_feedback", FEATURE).scale
        self.coarse = self.torque_step_pct >= COARSE_TORQUE_STEP_PCT
        self.ramp = plan.ramp_s
        self.guard = BandGuard(gap_s=rest.longest_gap_s if rest is not None else 0.0)
        self.move_first = 0  # the first sample of the running move
        self.home: float | None = None  # where the pilot started: the moves out and back rest there and a move out
        self.speed, self.cap = plan.speed_rpm, (plan.speed_limit_rpm, "speed")  # the test speed, its cap and bound
        self.torque_cap_pct = budget.torque_cap_pct(torque_limit)
        self.planned_s = plan.time_budget_s  # the time budget before _extended (set again once the pilot is done)

    def _beat(self, lead_s: float = 0.0) -> None:
        self.jogger.watch_inputs()
        # No dead-man on the drive (route none, waived): nothing watches the beat, and its writes would only
        # take samples' time on a slow line.
        bound = self.jogger.dead_man
        if bound is None or bound.bounded:
            # Before the next call: a sample, a position read, the alarm check and a move's settings at most.
            # ... and a stall as long as the longest seen so far.
            self.jogger.keep_alive(lead_s=max(4.0 * self.sampler.interval(), self.guard.gap_s) + lead_s)

    def _estimate_between_moves(self, settings: EstimatorSettings) -> InertiaEstimate:
        """An estimate while the drive holds between moves, the dead-man fed throughout (KeepAlive.while_computing:
        the two-mass scan makes one tens of ms, several hundred on a busy host, against DSX7E's 500 ms watchdog)."""
        trace = self.sampler.trace
        with self.sampler.paused():
            return self.jogger.keepalive.while_computing(lambda: self.estimate(trace, settings), self._beat)

    def sample(self) -> None:
        try:
            self.sampler.sample()
            self.guard.saw(self.sampler.pred)
        except TravelLimitReached:
            raise self._exceeded() from None

    def _exceeded(self) -> TravelExceeded:
        """The travel limit reached, in words that name its cause: a gap between samples (the host stalled) that let
        a host-timed move run on, where the motion had one (a stall in an earlier move leaves the axis that much
        further on: the creep adds up); else the loop overshooting its moves."""
        s, limit = self.sampler, self.plan.travel_limit_rev
        said = f"travel limit {limit:g} rev reached (the axis covered {s.travel_rev:.2f} rev): motion stopped; "
        gap, usual = self._longest_gap(0), self._usual_interval()
        if gap >= max(STALL_S, STALL_INTERVALS * usual):
            return TravelExceeded(
                said + f"a {1000 * gap:.0f} ms gap between samples (usually {1000 * usual:.2g} ms: the host stalled, "
                "a busy machine?) let a move that the host ends run on before it could be stopped, not the loop: run "
                "it again on a quieter host, or with more --travel"
            )
        return TravelExceeded(
            said + "the axis ran on past its moves: the loop overshoots (inertia ratio far off?): lower --max-speed "
            f"or allow more than {limit:g} rev with --travel"
        )

    def _longest_gap(self, first: int) -> float:
        """The longest time between two samples from sample `first` on, less the sampler's own pauses in it (a fit
        between moves: no stall of the host's); 0 with fewer than two."""
        trace = self.sampler.trace
        t = np.asarray(trace.t[max(0, first - 1) :])
        return float(np.max(host_gaps(t, paused_within(t, trace.paused)))) if t.size > 1 else 0.0

    def _usual_interval(self) -> float:
        """The median time between two samples so far."""
        t = self.sampler.trace.t
        gaps = sorted(b - a for a, b in itertools.pairwise(t))
        return gaps[len(gaps) // 2] if gaps else 0.0

    def _sample_timed(self) -> None:
        """A sample inside a move, its gap from the one before kept when it is the longest yet."""
        self.sample()
        self.guard.gap_s = max(self.guard.gap_s, self.sampler.interval())

    def move(self, direction: int, speed: float) -> tuple[float, float, float]:
        """One accelerate-then-stop move; returns (excursion so far in rev, peak |torque| in %, its acceleration's
        part in %: torque_swing)."""
        s, jogger, trace, guard = self.sampler, self.jogger, self.sampler.trace, self.guard
        first = self.move_first = len(trace.t)
        # After the pilot a segment route's move ends by itself, its own segment no longer than the travel band
        # leaves room for (BandGuard.own_room): the drive brakes it inside the band however late a stalled host
        # looks again (a 65-140 ms stall hid the ramp of a move whose segment ran past the band, and the stop came
        # too late: IS620P, load 37). The pilot stops by command, as an early stop (BandGuard.must_stop) does.
        full = speed / 60.0 * self.ramp  # the own segment that reaches the speed: up one ramp, down another
        jogger.start(
            direction,
            speed,
            eng_to_raw(self.jog_accel, self.ramp * 1000.0 * self.ramp_rpm / speed),
            self.ramp if guard.band is not None else None,
            guard.own_room(s.pred, direction, speed, full),
        )
        start = self.timing.now()
        own = jogger.own_segment_rev()
        guard.begin(s.pred, direction, speed, own, full)
        target = self._target(direction, speed) if own is None else None
        self.sample()
        while True:  # the drive's ramp reaches the speed in ramp_s; a host-timed move aims at its target
            elapsed = self.timing.now() - start
            if elapsed >= self.ramp and not self._short_of(target, direction, speed, elapsed):
                break
            self._sample_timed()
            if guard.must_stop(s.pred, abs(trace.speed[-1]), self.ramp, s.interval()):
                break
            if self._beyond(target, direction):  # a stall let it run on: it stops where the next one starts from
                break
        jogger.command(0)
        stop = self.timing.now()
        at_stop, v_stop = s.pred, abs(trace.speed[-1]) if trace.speed else 0.0
        self.sample()  # after the stop's own writes: no stall
        # Between moves the next one may start once a reading falls inside the stop's band: no claim to the user rests
        # on it (the stop's proof is RestWatch's band and mean). Known cost: a heavy load's ringing loop shows such a
        # reading on its way through zero, and the next move starts mid-swing (IS620P 57600, loads of 37-50 with 1 %
        # noise: at -123..+329 rpm; the swings add up to the travel limit). RestWatch here (two readings over
        # SETTLE_S) cured those two and cost SDC 9600 acceptance and DSX7E 19200's noise-free fits their 3 sigma on
        # the bench: not landed.
        while self.timing.now() - stop < 3 * self.ramp + 0.5:
            self._sample_timed()
            if self.timing.now() - stop >= self.ramp and abs(trace.speed[-1]) < self.stop_band:
                break
        # At rest for two samples and, where the next move's settings go in fewer requests (Mover.folds), half a
        # ramp: the loop gets the time to settle that those requests' own time gave it (the speed route keeps its
        # rest).
        rest = self.timing.now() + (REST_RAMPS * self.ramp if self.jogger.folds else 0.0)
        self.sample()
        self.sample()
        while self.timing.now() < rest:
            self.sample()
        guard.ended()
        # The coast after a stop command; a move whose own segment braked it ran past that, not past a command
        # (BandGuard.ended: taken as a lag, it was read at the low speed the host saw after its ramp, up to 1.2 s).
        if v_stop > self.stop_band and not jogger.ended_itself:
            guard.coasted(abs(s.pred - at_stop) - v_stop * v_stop * self.ramp / (2 * speed) / 60.0, v_stop)
        active = active_alarm(self.drive)
        if active:
            raise IdentificationFailed(f"the drive stopped the identification with alarm {active}" + self._starved())
        peak = max((abs(q) for q in trace.torque[first:]), default=0.0)
        return s.travel_rev, peak, torque_swing(trace.speed[first:], trace.torque[first:], self.torque_step_pct)

    def _starved(self) -> str:
        """Where the drive's own watchdog may have stopped the motion because the host stalled: the words that say
        so (after an alarm; Mover.starved, from its looks and the samples' longest gap); "" otherwise."""
        return self.jogger.starved(self._longest_gap(self.move_first))

    def _target(self, direction: int, speed: float) -> float | None:
        """Where a host-timed move out and back should come to rest: the forward move a move's travel (stretched as
        the pilot showed) beyond where the pilot started, the reverse one there. Ending each move by position, not
        only by time, keeps a move that a host stall let run on from shifting every later one: the next move ends
        where it was to end (issue 31: the axis crept 0.2-0.3 rev a cycle until the travel limit). None before the
        pilot's band and for one direction, whose moves add up."""
        if self.guard.band is None or self.home is None or len(self.plan.directions) < 2:
            return None
        return self.home + (speed / 60.0 * self.ramp * self.guard.stretch if direction > 0 else 0.0)

    def _tolerance(self, speed: float) -> float:
        """How far from its target a move may rest without being ended early or carried on (a move's travel varies
        with the loop's lag and the sampling): a tenth of it."""
        return TARGET_TOLERANCE * speed / 60.0 * self.ramp * self.guard.stretch

    def _beyond(self, target: float | None, direction: int) -> bool:
        if target is None or not self.sampler.trace.speed:
            return False
        v = abs(self.sampler.trace.speed[-1])
        rest = self.guard.rest_at(self.sampler.pred, v, self.ramp, self.sampler.interval())
        return direction * (rest - target) > self._tolerance(self.guard.speed)

    def _short_of(self, target: float | None, direction: int, speed: float, elapsed: float) -> bool:
        """Whether a move whose ramp has ended would rest short of its target (the move before it ran on): it runs
        on at its speed, for at most CATCH_UP_RAMPS more ramps, until it would rest there."""
        if target is None or elapsed >= (1.0 + CATCH_UP_RAMPS) * self.ramp or not self.sampler.trace.speed:
            return False
        v = abs(self.sampler.trace.speed[-1])
        rest = self.guard.rest_at(self.sampler.pred, v, self.ramp, self.sampler.interval())
        return direction * (target - rest) > self._tolerance(speed)

    def pilot(self, hold: StableHold, settings: EstimatorSettings) -> float:
        """Pilot cycle at reduced speed: how far the axis really goes per nominal revolution (a badly matched speed
        loop overshoots) and how much torque the acceleration takes, before the full test; returns its speed.
        `hold` keeps a position hold stable for the unknown load; the pilot's rough estimate then configures it."""
        plan = self.plan
        both = len(plan.directions) > 1
        pilot = plan.speed_rpm * PILOT_SHARE
        hold.before_pilot()
        if self.progress:
            self.progress(f"pilot move at {pilot:.0f} rpm")
        excursion, peak, swing = 0.0, 0.0, 0.0
        self.sample()  # the axis's real position: the travel band is around it, not around 0
        origin = self.home = self.sampler.pred
        for direction in plan.directions:
            excursion, pk, sw = self.move(direction, pilot)
            peak, swing = max(peak, pk), max(swing, sw)
        if hold.active:
            hold.after_pilot(self._estimate_between_moves(pilot_settings(settings)))
        if self._short():
            self._check_travel(self._estimate_between_moves(replace(settings, **ROUGH)))
        nominal = pilot / 60.0 * plan.ramp_s * (1 if both else len(plan.directions))
        limit_rev = plan.travel_limit_rev
        lo = origin - 0.05 * limit_rev if both or plan.directions[0] > 0 else origin - 0.9 * limit_rev
        self.guard.band, self.guard.stretch = (lo, lo + 0.9 * limit_rev), max(1.0, excursion / nominal)
        return self._test_speed(pilot, excursion, peak, swing)

    def _short(self) -> bool:
        """Whether the travel allowed does not serve every load (the plan's needs): the pilot's load decides."""
        needs = self.plan.needs
        return needs is not None and not needs.enough

    def _check_travel(self, rough: InertiaEstimate) -> None:
        """After the pilot: the travel and time the load it showed needs, taken at its ratio less two of its sigmas
        (a pilot is rough). Where the travel allowed serves that load: the time budget it needs. Else TravelNeeded
        with the travel that serves it; where none does, the next heavier load is taken (less one sigma, as shown,
        then the heavier ratios of budget.LOAD_RATIOS): the motion goes on where the travel allowed serves that one
        (no travel would serve the lighter ones), else its travel is named (a longer travel also gives a stronger
        pilot, which tells the load better) where it is beyond PILOT_SLACK of the travel allowed and the user did
        not give the travel (a travel named and followed is not asked again); else the motion goes on with the
        longest time budget and the fit decides."""
        needs = self.plan.needs
        assert needs is not None
        ratio, std = rough.load_ratio, rough.ratio_std
        # A pilot tells the load where J comes out positive, less than 100 % uncertain, and from speed changes that
        # clear the noise as the final fit's must (a quarter of the speed on a noisy reading: DSX7E 19200 with 1 %
        # noise showed 1.4 +- 0.82 for a load of 5, and the travel the motor alone needs, 19.5 rev, was named where
        # 6 rev serve that load). Where it cannot, the travel allowed serves some loads (else nothing would have
        # moved, and the needs said so before moving): the motion goes on with the longest time budget, and the
        # fit decides (a refusal names the travel its run showed was needed).
        tells = math.isfinite(ratio) and math.isfinite(std) and ratio > -1.0 and std < 1.0 + ratio
        if not tells or not rough.excitation >= EstimatorSettings().min_excitation:
            self.plan = self.plan.budgeted(budget.MAX_TIME_S)
            if self.progress:
                self.progress(f"pilot: it cannot tell the load; time budget {self.plan.time_budget_s:.0f} s")
            return
        lows = [max(0.0, ratio - k * std) for k in (2.0, 1.0, 0.0)]
        line = needs.line
        # How far this machine's fit stays from the model, as the pilot (a quarter of the speed) showed it.
        model, pilot_rpm, _bound = budget.predicted(
            line, ratio, needs.allowed_rev * PILOT_SHARE, 2 * len(self.plan.directions), floor=False
        )
        seen = rough.j_std_kgm2 / rough.j_total_kgm2
        if math.isfinite(model) and model > 0 and math.isfinite(seen):
            # scaled as a remedy scales it (budget.more_travel): down to the best efficiency measured, at most, and
            # not below the model's where the reading's steps hid the pilot's acceleration (budget.steps_hide)
            hidden = budget.steps_hide(line, budget.accel_torque_pct(line, ratio, pilot_rpm))
            floor = 1.0 if hidden else budget.BEST_EFFICIENCY / budget.EFFICIENCY
            line = replace(line, efficiency=min(PILOT_EFFICIENCY_CAP, max(floor, seen / model)))
        last = None
        for r in lows + [r for r in budget.LOAD_RATIOS if r > lows[-1]]:
            fits = budget.within(line, r, needs.allowed_rev, needs.target)
            if fits.reachable:
                self.plan = self.plan.budgeted(fits.time_s)
                if self.progress:
                    self.progress(f"pilot: {fits.words(needs.target)}; time budget {self.plan.time_budget_s:.0f} s")
                return
            last = budget.need(line, r, needs.target)
            # the closest travel, where only the budget's margin fails, for the lightest load not ruled out: a
            # heavier load's travel was refused again (SDC 19 samples/s, the motor alone with 30 % friction and 40 %
            # gravity: 14.5 rev named for a load of 0.5, refused at 2.1 %; 20.5 identified it)
            if last.nameable(needs.target):
                break
        assert last is not None
        named = last.nameable(needs.target)
        if self.plan.travel_given or (named and last.travel_rev <= PILOT_SLACK * needs.allowed_rev):
            self.plan = self.plan.budgeted(budget.MAX_TIME_S)
            if self.progress:
                allowed = "given" if self.plan.travel_given else "allowed, near it"
                self.progress(
                    f"pilot: {last.words(needs.target)}, with {needs.allowed_rev:g} rev {allowed}: the fit decides; "
                    f"time budget {self.plan.time_budget_s:.0f} s"
                )
            return
        raise TravelNeeded(
            f"stopped after the pilot: it shows a load ratio of {ratio:.2g} ± {std:.2g}; {last.words(needs.target)}, "
            f"more than the {needs.allowed_rev:g} rev "
            "allowed" + (f": where the axis has room, --travel {last.travel_rev:g}" if named else ""),
            last.travel_rev if named else math.nan,
            last.time_s if named else math.nan,
            moved=True,
        )

    def _test_speed(self, pilot: float, excursion: float, peak: float, swing: float) -> float:
        """The planned speed, within the travel band and the torque the pilot extrapolates to (its acceleration's
        part, swing, grows with the speed and falls with slower ramps; budget.torque_speed_cap)."""
        plan = self.plan
        both = len(plan.directions) > 1
        speed = plan.speed_rpm  # excursion and torque grow in proportion to the speed at a fixed ramp time
        guard = self.guard
        if guard.stretch > 1.5:
            # The loop cannot follow the ramps (far-off inertia ratio: an under-damped loop): slower ramps at
            # a lower speed (the same travel) keep its swing inside the travel band.
            factor = min(2.0, guard.stretch / 1.5, 0.5 / self.ramp)
            self.ramp, speed = self.ramp * factor, speed / factor
            guard.stretch /= factor
        if excursion > 0:
            room = 0.85 * plan.travel_limit_rev - (excursion if not both else 0.0)
            speed = min(speed, pilot * plan.ramp_s / self.ramp * room / (excursion * (plan.repeats if not both else 1)))
        if peak > 0:
            # The whole peak scaled to a share of the drive's limit: headroom for a loop that does not know the load
            # yet. Where the torque reading's steps would then floor the fit, the acceleration's part alone, the rest
            # within the limit, as the budget plans (budget.torque_speed_cap); elsewhere that speed buys nothing and
            # a detuned loop overshoots more (IS620P, load 20 with 30 % friction: 1069 rpm for 666 ran 0.28 rev
            # past its band, where 666 was accepted).
            swing *= plan.ramp_s / self.ramp
            cap = pilot * self.torque_cap_pct / peak
            if self._steps_floor(swing * cap / pilot):
                cap = budget.torque_speed_cap(pilot, peak, swing, self.torque_limit)
            self.cap = min(self.cap, (cap, "torque"))
        self.speed = min(speed, self.cap[0])
        return self.speed

    def _steps_floor(self, tau_pct: float) -> bool:
        """Whether moves with this acceleration torque would leave a floor from the torque reading's steps beyond
        STEP_FLOOR_SHARE of the fit's limit (budget.step_floor, over the most moves the plan runs)."""
        needs = self.plan.needs
        if needs is None:
            return False
        moves = len(self.plan.directions) * self.plan.repeats
        return budget.step_floor(needs.line, tau_pct, moves) > STEP_FLOOR_SHARE * needs.target

    def _dithered(self, cycle: int, speed: float) -> tuple[float, float]:
        """Ramp and speed of a cycle: a torque read in coarse steps gets a different acceleration in every cycle
        (planning.dithered). A finer reading only where the planned ramp sits at its floor (a fast line), by the same
        shorter ramps at the same speed: stronger accelerations for light loads, where the floor, not the samples a
        ramp needs, kept them weak; on slower lines the planned ramps stay."""
        if not self.coarse and self.plan.ramp_s > MIN_RAMP_S:
            return self.ramp, speed
        # No shorter than twice the longest gap yet: a host stall must not take a whole ramp before the stop guard
        # sees the axis again.
        ramp, slower = dithered(self.ramp, speed, cycle, self.sampler.rate(), STALL_RAMPS * self.guard.gap_s)
        return ramp, slower if self.coarse else speed

    def cycles(self, speed: float, settings: EstimatorSettings) -> int:
        """The planned cycles (adaptive: until the estimate is precise enough, within the time budget the line's
        needs set before the motion, or the pilot after it; extended where the travel is short of what the lightest
        load needs: _extended)."""
        s = self.sampler
        self.planned_s = self.plan.time_budget_s  # as the line's needs or the pilot set it, before any extension
        # The next cycle takes as long as the longest so far (the pilot's before the first: it also holds the set-up).
        cycle_s = s.elapsed() * 1.1
        done, began, rep = 0, 0.0, 0
        while rep < self.plan.repeats:
            if rep >= 1:
                cycle_s = max(s.elapsed() - began, cycle_s if rep >= 2 else 0.0) * 1.05
            began = s.elapsed()
            if self.plan.adaptive and rep >= 2:
                due = s.elapsed() + cycle_s > self.plan.time_budget_s
                if due and (self.plan.needs is None or self.plan.needs.enough) and not self._host_late():
                    break
                est = self._estimate_between_moves(settings)
                if est.ok and est.j_std_kgm2 <= 0.5 * settings.max_rel_uncertainty * est.j_total_kgm2:
                    break
                if due and not self._extended(est, settings, cycle_s):
                    break
            base = self.ramp
            self.ramp, move_speed = self._dithered(rep, speed)
            try:
                for direction in self.plan.directions:
                    if self.progress:
                        self.progress(
                            f"move {rep + 1}/{self.plan.repeats} {'forward' if direction > 0 else 'reverse'} "
                            f"at {move_speed:.0f} rpm"
                        )
                    self.move(direction, move_speed)
            finally:
                self.ramp = base
            done += 1
            rep += 1
        return done

    def _extended(self, est: InertiaEstimate, settings: EstimatorSettings, cycle_s: float) -> bool:
        """At the end of the time budget, on a line whose travel does not serve every load (MotionPlan.needs): a
        budget extended (up to the time limit said before moving, MotionPlan.time_limit_s) to the time in which this
        estimate, falling as one over the root of the time, is projected to reach EXTEND_AIM of the limit, where it
        does; False where not. There time is what buys precision, and a travel named before (or by a refusal) gets
        the time it was named with. Where the travel serves every load the budget stands (a longer log makes a rigid
        load's speed-noise artefact stand out in sigmas, and it was then blamed on backlash), unless the host was
        late (_host_late): then the line's samples were there but the host lost them, and time buys them back, up to
        budget.LATE_TIME_FACTOR times the budget planned (and the time limit)."""
        needs, late = self.plan.needs, self._host_late()
        if needs is None or (needs.enough and not late):
            return False
        elapsed = self.sampler.elapsed()
        rel = _relative_std(est)
        if not (math.isfinite(rel) and rel > 0 and math.isfinite(est.load_ratio)) or est.n_windows == 0:
            if not late:
                return False
            rel = LATE_EXTEND * EXTEND_AIM * settings.max_rel_uncertainty  # refused outright: the time scaled
        projected = elapsed * (rel / (EXTEND_AIM * settings.max_rel_uncertainty)) ** 2
        if late:  # the host, not the line, lost the samples: time buys them back, within LATE_TIME_FACTOR of the plan
            cap = budget.LATE_TIME_FACTOR * self.planned_s if needs.enough else math.inf
            projected = min(projected, min(cap, self.plan.time_limit_s) - cycle_s)
        if projected + cycle_s > self.plan.time_limit_s or projected <= self.plan.time_budget_s:
            return False
        self.plan = self.plan.budgeted(projected + cycle_s)
        if self.progress:
            self.progress(f"J {100 * rel:.1f} % uncertain after {elapsed:.0f} s: time budget {projected:.0f} s")
        return True

    def _host_late(self) -> bool:
        """Whether the host took a share of the samples the line gave (LATE_NAMED of them left out of the fit: their
        exchange overran the line's time) or stalled while the axis moved: time, not travel, then buys them back."""
        trace = self.sampler.trace
        if trace.late > LATE_NAMED * len(trace.t):
            return True
        fitted_t, speed, _torque, _position = trace.fitted()
        t = np.asarray(fitted_t)
        return stall(t, np.asarray(speed), paused_within(t, trace.paused))[0] > 0

    def _late_words(self) -> str:
        """The samples the host's lateness left out, in words for a refusal ("" where few were)."""
        trace = self.sampler.trace
        if trace.late <= LATE_NAMED * len(trace.t):
            return ""
        return (
            f" ({trace.late} of {len(trace.t)} samples left out of the fit: their exchanges overran the line's time, "
            "the host was late, a busy machine?)"
        )

    def _no_cure(self, est: InertiaEstimate, bound: RateBound | None = None) -> str:
        """Where the line's budget found no travel that cures a refusal more excitation would: so said, instead of
        advice (stronger accelerations, more moves) that the motion planned within the line's limits already tried;
        where the sampling rate bounds it (_rate_bound), that, and what would help on this drive."""
        needs = self.plan.needs
        if bound is not None:
            return (
                f"no travel cures it: {100 * bound.rel:.1f} % of it is what a coupling stiffer than the "
                f"{bound.top_hz:.1f} Hz the resonance scan searches at {bound.rate:.0f} samples/s could add, and "
                f"stronger or longer moves within what the drive allows keep it; {self._faster()}"
            )
        if needs is None or not math.isfinite(est.shortfall):
            return ""
        return (
            f"no travel up to {budget.MAX_TRAVEL_REV:g} rev brings it to {100 * needs.target:g} % within "
            f"{budget.MAX_TIME_S:g} s on this line (the speed or the torque the drive allows bounds the moves)"
        )

    def _faster(self) -> str:
        """What lowers a share the sampling rate bounds on this drive: a faster line where its profile can raise it,
        the drive's own identification where it has one, else nothing."""
        p = self.drive.profile
        if p.boost.available:
            return "a faster line lowers it (this drive's is raised for the identification unless --no-boost)"
        said = "a faster line would lower it, and this drive's profile raises none (serial.boost)"
        if p.role("inertia_id") is not None:
            return said + ": the drive's own identification (--method drive) does not sample over the line"
        return said + ": nothing on this drive does"

    def _rate_bound(self, est: InertiaEstimate, cycles: int) -> RateBound | None:
        """The refusal's share that the sampling rate bounds (fit.estimate.RateBound) where no motion the drive allows
        brings it and the fit's own part near the limit: the strongest moves (up to the speed or the torque the
        drive allows, over the most travel and time named) in windows no shorter than this run's (the speed change a
        window needs comes no sooner), their information short of what releases the share. None elsewhere, and where
        the windows would shorten: the share of other windows sets no scale for them (a weak 2 rev run, its windows
        stretched to reach the speed change, is cured by the travel its refusal names)."""
        needs, bound = self.plan.needs, est.rate_bound
        if needs is None or bound is None or not (est.j_total_kgm2 > 0 and est.excitation > 0 and self.speed > 0):
            return None
        line, travel = self._remedy_line(), self.plan.travel_limit_rev
        ratio = _load_shown(est)
        per_rev, moves, most = self.speed / travel, max(2 * cycles, 2), budget.moves_in(line, budget.MAX_TIME_S)
        speed = budget.predicted(line, ratio, budget.MAX_TRAVEL_REV, most, per_rev)[1]
        stronger = speed / self.speed  # the acceleration at the same ramps, and the speed change a window sees
        if math.ceil(est.window_intervals * EstimatorSettings().min_excitation / (est.excitation * stronger)) < (
            est.window_intervals
        ):
            return None
        gain = stronger * math.sqrt(max(most, moves) / moves)  # the information: acceleration x root of the samples
        # over the limit by more than a run's figure may misjudge it (the margin a remedy aims inside, the other way)
        beyond = needs.target / budget.TARGET_SHARE
        own = est.fit_std_kgm2 / est.j_total_kgm2
        return bound if math.hypot(own / gain, bound.at(gain)) > beyond else None

    def _remedy_line(self) -> budget.Line:
        """The line a remedy is planned on: the needs' own, its speed held to the torque cap this run's pilot set
        (_test_speed) where the moves stopped at it, not at the travel, and the plan's speed is at its limit already
        (within SAME_PILOT): a longer travel then runs the same pilot, which sets the same cap, and the same moves.
        Where the plan's speed can still grow, a longer travel's faster pilot sets a cap this one does not tell (a
        slow pilot's torque spread is friction and gravity as much as acceleration: SD25's load of 1 with 30 %
        friction and 40 % gravity was capped at 175 rpm at 2 rev and ran at 3000 at the 34.5 rev named)."""
        needs, plan = self.plan.needs, self.plan
        assert needs is not None
        line = needs.line
        cap, what = self.cap
        if what != "torque" or self.speed < cap or not plan.speed_rpm * SAME_PILOT >= plan.speed_limit_rpm:
            return line
        return replace(line, speed_cap_rpm=min(line.speed_cap_rpm, cap * plan.speed_limit_rpm / plan.speed_rpm))

    def _remedy(self, est: InertiaEstimate, cycles: int) -> Remedy | None:
        """A longer travel for a refusal that stronger accelerations cure: the least with which the line's budget
        (tuning.budget), scaled to what this run showed, reaches the limit within its time; none where no travel
        does (the speed or the torque the drive may spend bounds the moves, or the line is too slow), so a remedy
        offered is one that passed the check the motion is planned by; where only that check's margin fails, the
        strongest motion the drive allows, as one that may not be enough, where it is predicted within the limit. A
        plan of the user's own ramps, repeats or one direction (no budget): the travel that covers the shortfall
        (planning.remedy)."""
        needs = self.plan.needs
        if needs is None:
            return remedy(self.plan.travel_limit_rev, est.shortfall, self.speed, *self.cap)
        if not math.isfinite(est.shortfall):
            return None
        rel = _relative_std(est)
        rel = math.sqrt(max(0.0, rel**2 - est.floor_rel**2)) if math.isfinite(est.floor_rel) else rel
        low = est.excitation if est.excitation < EstimatorSettings().min_excitation else math.nan
        # No fit stood (too little excitation): the load is not known, and the travel named is the least with which
        # the lightest load this line can serve at all would reach the limit.
        ratios = [max(est.load_ratio, 0.0)] if math.isfinite(est.load_ratio) else budget.LOAD_RATIOS
        travel = self.plan.travel_limit_rev
        line, target = self._remedy_line(), needs.target
        for closest in (False, True):
            found = next(
                (
                    need
                    for r in ratios
                    if (need := budget.more_travel(line, r, travel, 2 * cycles, rel, target, low, self.speed, closest))
                    is not None
                ),
                None,
            )
            if found is not None:
                gain = found.travel_rev / travel
                return Remedy(travel, found.travel_rev, gain, not closest, found.bound, found.time_s)
        return self._strongest(est)

    def _strongest(self, est: InertiaEstimate) -> Remedy | None:
        """Where the rigid fit alone was within the limit and what was added to it took it over (a model check's
        widening, such as a coupling stiffer than the log resolves, not ruled out; the torque reading's floor): the
        strongest motion the drive allows, as one that may not be enough. The line's model scaled to the widened
        uncertainty said no travel would do (DSX7E 115200, load 37, 1 % noise: the fit alone 1.3 %, widened to
        3.6 %), where 16 rev identified it within 3 sigma in 5 of 5 seeds: the widening falls with stronger moves
        far faster than the model's noise does."""
        needs = self.plan.needs
        limit = EstimatorSettings().max_rel_uncertainty
        if needs is None or not est.j_total_kgm2 > 0 or not est.fit_std_kgm2 <= limit * est.j_total_kgm2:
            return None
        ratio = _load_shown(est)
        travel = self.plan.travel_limit_rev
        found = budget.strongest_travel(self._remedy_line(), ratio, travel, needs.target, self.speed)
        if found is None:
            return None
        return Remedy(travel, found.travel_rev, found.travel_rev / travel, False, found.bound, found.time_s)

    def run(self) -> Result:
        settings = EstimatorSettings(fit_load_torque=len(self.plan.directions) > 1)
        jogger = self.jogger
        # However the motion ends, the stop sequence waits (bounded) for the axis to rest inside this motion's speed
        # band before the servo goes off (a ringing loop swings through zero), and proves it; the drive's protections
        # (protect_for, above) are set inside it before the first move and put back with the motion's settings.
        with jogger.stopping(band_rpm=self.stop_band, need_ramp=True) as saved:
            hold = StableHold(self.drive, jogger.route.kind, saved)
            cycles = self.cycles(self.pilot(hold, settings), settings)
        s = self.sampler
        rate = s.rate()
        est = self.estimate(s.trace, settings)
        result = Result(
            "host", self.old_ratio, est.load_ratio, est, s.trace, self.plan, s.travel_rev, s.elapsed(), rate, cycles
        )
        if not est.ok:
            bound = self._rate_bound(est, cycles)
            cure = self._remedy(est, cycles) if bound is None else None
            advice = cure.words() if cure is not None else self._no_cure(est, bound) or est.advice
            raise IdentificationRefused(
                f"identification refused: {est.reason}{self._late_words()}" + (f"; {advice}" if advice else ""),
                result,
                cure,
            )
        return result
