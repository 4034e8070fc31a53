"""Inertia identification wizard: pre-checks, a bounded back-and-forth JOG motion with sampling, estimation, result.

Host method: speed-controlled moves through the profile's JOG roles with the same dead-man keep-alive as `jog`,
speed and torque sampled over Modbus, then the integral-form fit of servotool.tuning.estimator.
Drive method: triggers the profile's drive-side identification (role inertia_id) and reads its result.
"""

from __future__ import annotations

import csv
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from servotool import alarms
from servotool.codec import raw_to_eng
from servotool.drive import Drive, plan_reads
from servotool.errors import ServoError, UsageError
from servotool.gain_units import from_canonical
from servotool.motion import Jogger, keepalive_interval_s, motion_route, servo_is_on
from servotool.params import ram_writes
from servotool.profile import Entry, Profile, status_bit
from servotool.tuning.estimator import EstimatorSettings, InertiaEstimate, estimate_inertia
from servotool.tuning.gains import GainSuggestion, suggest_gains

FEATURE = "tune inertia"
GAIN_ROLES = {"speed_loop_gain": "speed_loop_gain_hz", "speed_loop_integral": "speed_integral_ms",
              "position_loop_gain": "position_loop_gain_per_s", "torque_filter": "torque_filter_ms"}


class IdentificationFailed(ServoError):
    """The motion ran but the result is not trustworthy (or the drive reported failure)."""

    exit_code = 1


class TravelExceeded(IdentificationFailed):
    """The axis moved further than the travel limit; the motion was stopped."""


class Timing(Protocol):
    def now(self) -> float: ...
    def sleep(self, seconds: float) -> None: ...


class RealTiming:
    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        time.sleep(max(0.0, seconds))


DEFAULT_SAMPLES_PER_S = 40.0
"""Sampling rate assumed when planning without a measured one (a 38400-baud link)."""
SAMPLES_PER_RAMP = 7.0
"""Automatic ramps last this many sampling intervals of the rest check (the motion samples about 2/3 as fast:
position reads and keep-alives share the link). Fewer leave too few windows between torque steps and let the axis
run further between two samples than the travel guard can foresee; more lower the acceleration (it falls with the
square of the ramp time at a fixed travel), and a low-inertia axis with a noisy torque reading then cannot reach
the precision within the time budget (10 intervals: 2.0-2.7 % at 19200 baud with 0.4 % rated torque noise)."""
TIME_BUDGET_S = 8.8
"""Automatic repeats stop before the motion (with its pilot) would take longer than this."""
TORQUE_SHARE = 0.6
"""The test acceleration is scaled so the pilot's peak torque, extrapolated, stays below this share of the limit."""
PILOT_SHARE = 0.25
"""The pilot moves at this share of the planned speed: a badly matched speed loop can overshoot its travel
several times over, and the pilot must stay inside the limit even then."""


@dataclass(frozen=True)
class MotionPlan:
    speed_rpm: float
    ramp_s: float            # time to reach speed (and to stop)
    directions: tuple[int, ...]
    repeats: int             # move cycles; with `adaptive` the most that will run
    travel_limit_rev: float
    adaptive: bool = False   # stop repeating once the estimate is precise enough (and within TIME_BUDGET_S)

    @property
    def move_travel_rev(self) -> float:
        """Travel of one accelerate-then-stop move (triangular speed profile)."""
        return self.speed_rpm / 60.0 * self.ramp_s

    @property
    def excursion_rev(self) -> float:
        """Range of positions covered. Both directions: one move out and back (the slower pilot stays inside).
        One direction: every move adds up, and so does the pilot."""
        if len(self.directions) > 1:
            return self.move_travel_rev
        return self.move_travel_rev * (self.repeats + PILOT_SHARE)

    @property
    def duration_s(self) -> float:
        moves = len(self.directions) * (self.repeats + 1)   # + the pilot
        return min(moves * (2 * self.ramp_s + 0.1), TIME_BUDGET_S if self.adaptive else math.inf)

    def describe(self) -> str:
        names = {1: "forward", -1: "reverse"}
        seq = " then ".join(names[d] for d in self.directions)
        count = f"up to {self.repeats}" if self.adaptive else f"{self.repeats}"
        return (f"{count} x ({seq}) moves to {self.speed_rpm:.0f} rpm, {self.ramp_s * 1000:.0f} ms ramps "
                f"({self.speed_rpm / self.ramp_s:.0f} rpm/s), {self.move_travel_rev:.2f} rev per move, "
                f"{self.excursion_rev:.2f} rev of travel in all (limit {self.travel_limit_rev:g} rev), about "
                f"{self.duration_s:.1f} s; a pilot move at a quarter of that speed first")


def plan_motion(profile: Profile, *, max_speed: float | None, accel_time_ms: float | None, travel_rev: float,
                direction: str, repeats: int | None, samples_per_s: float | None = None) -> MotionPlan:
    """Choose speed and ramp so the motion stays inside the travel limit; refuse what cannot.

    accel_time_ms None: ramps of SAMPLES_PER_RAMP sampling intervals at samples_per_s (the measured link rate).
    repeats None: cycles are repeated until the estimate is precise enough, within TIME_BUDGET_S.
    """
    if not (math.isfinite(travel_rev) and travel_rev > 0):
        raise UsageError("--travel must be a number > 0 revolutions")
    if repeats is not None and not 1 <= repeats <= 20:
        raise UsageError("--repeats must be 1..20")
    dirs = {"both": (1, -1), "forward": (1,), "reverse": (-1,)}.get(direction)
    if dirs is None:
        raise UsageError("--direction must be both, forward or reverse")
    if accel_time_ms is None:
        rate = samples_per_s if samples_per_s and math.isfinite(samples_per_s) else DEFAULT_SAMPLES_PER_S
        ramp = min(0.5, max(0.1, SAMPLES_PER_RAMP / rate))
    else:
        if not (math.isfinite(accel_time_ms) and 20 <= accel_time_ms <= 5000):
            raise UsageError("--accel-time must be 20..5000 ms")
        ramp = accel_time_ms / 1000.0
    adaptive = repeats is None and len(dirs) > 1
    # One direction cannot stop early: the travel of every move is reserved up front.
    cycles = repeats if repeats is not None else (20 if adaptive else 6)
    # Keep a margin of 10 % for overshoot.
    budget = 0.9 * travel_rev / (1.0 if len(dirs) > 1 else cycles + PILOT_SHARE)
    speed = budget / ramp * 60.0
    motor = profile.motor
    limit = motor.rated_speed_rpm if motor else 3000.0
    if max_speed is not None:
        if not (math.isfinite(max_speed) and max_speed > 0):
            raise UsageError("--max-speed must be a number > 0")
        limit = min(limit, max_speed)
    speed = min(speed, limit)
    plan = MotionPlan(speed, ramp, dirs, cycles, travel_rev, adaptive)
    if speed < 30.0:
        raise UsageError(f"travel limit {travel_rev:g} rev is too small for an identification with "
                         f"{ramp * 1000:.0f} ms ramps (needs at least {30 / 60 * ramp / 0.9:.2f} rev per move); "
                         "raise --travel, shorten --accel-time" + (" or use --direction both" if len(dirs) == 1
                                                                    else ""))
    if plan.excursion_rev > travel_rev:
        raise UsageError(f"the motion needs {plan.excursion_rev:.2f} rev, over the --travel limit {travel_rev:g}")
    return plan


def plan_host_motion(drive: Drive, timing: Timing | None = None, *, max_speed: float | None = None,
                     accel_time_ms: float | None = None, travel_rev: float = 2.0, direction: str = "both",
                     repeats: int | None = None) -> tuple[MotionPlan, RestCheck]:
    """The host method's motion as every caller runs it (CLI, plans, bench): the options checked before anything is
    read, the axis checked at rest, then the plan for the sampling rate that check measured.

    accel_time_ms and repeats None: automatic (ramps from the sampling rate, repeats until precise enough).
    """
    options = {"max_speed": max_speed, "accel_time_ms": accel_time_ms, "travel_rev": travel_rev,
               "direction": direction, "repeats": repeats}
    plan_motion(drive.profile, **options)
    rest = check_at_rest(drive, timing)
    return plan_motion(drive.profile, **options, samples_per_s=rest.samples_per_s), rest


def preflight(drive: Drive, method: str) -> None:
    """Link, roles, alarm and servo state; raises with one clear line."""
    p = drive.profile
    # Host identification measures J without the drive's ratio parameter (SDC maps none): it then only reports.
    need = ["speed_feedback", "torque_feedback"]
    need += ["jog_accel"] if method == "host" else ["inertia_ratio", "inertia_id"]
    for role in need:
        p.need_role(role, f"{FEATURE} --method {method}")
    if method == "host":
        motion_route(p, f"{FEATURE} --method {method}")   # a JOG trigger or speed reference + servo-on
    else:
        status = p.role("servo_status")
        if status is None or status_bit(status, "identifying") is None:
            # Without it the end could only be guessed: a timeout would report failure after a good run.
            raise UsageError(f"{FEATURE} --method drive: profile {p.id} maps no status bit that shows the "
                             "drive's identification running, so its end cannot be seen over Modbus; use "
                             "--method host")
    if p.motor is None:
        raise UsageError(f"{FEATURE} needs the motor data (rated torque, rotor inertia) in profile {p.id}")
    active = active_alarm(drive)
    if active:
        raise UsageError(f"refusing to move: alarm {active} is active (clear it first)")
    if servo_is_on(drive) or (method == "host" and Jogger(drive, feature=FEATURE).servo_already_on()):
        raise UsageError("refusing to move: the servo is on (enabled from elsewhere); switch it off first")


def active_alarm(drive: Drive) -> str | None:
    """'CODE name' of an alarm seen active on two reads in a row (one stray reply is no alarm), else None."""
    state = alarms.confirmed(drive)
    return f"{state.display} {state.name}" if state is not None else None


@dataclass(frozen=True)
class RestCheck:
    """The axis observed with the servo off, before any motion."""

    samples_per_s: float
    speed_noise_rpm: float
    mean_speed_rpm: float
    drift_rev: float | None   # position change over the check (None: no position feedback)


def check_at_rest(drive: Drive, timing: Timing | None = None, duration_s: float = 0.3) -> RestCheck:
    """Sample the idle axis: it must stand still (a load torque with no brake drops it as soon as nothing holds it).

    Also measures what the motion plan needs: the link's sampling rate and the speed reading's noise.
    """
    p, timing = drive.profile, timing or RealTiming()
    speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
    pos_e = p.role("position_feedback")
    counts = p.motor.counts_per_rev if p.motor else 1
    pos0 = drive.read_entries([pos_e])[0].raw / counts if pos_e else None
    t0 = timing.now()
    speeds: list[float] = []
    while timing.now() - t0 < duration_s or len(speeds) < 5:
        readings = drive.read_entries([speed_e, torque_e])
        speeds.append(float(raw_to_eng(speed_e, readings[0].raw)))
    elapsed = timing.now() - t0
    drift = abs(drive.read_entries([pos_e])[0].raw / counts - pos0) if pos_e and pos0 is not None else None
    mean = sum(speeds) / len(speeds)
    # Speed noise from successive differences: insensitive to a slow drift.
    diffs = [b - a for a, b in itertools.pairwise(speeds)]
    noise = math.sqrt(sum(d * d for d in diffs) / (2 * len(diffs))) if diffs else 0.0
    rest = RestCheck(len(speeds) / elapsed if elapsed > 0 else DEFAULT_SAMPLES_PER_S, noise, mean, drift)
    moving = (drift is not None and drift > 0.01) or abs(mean) > max(5.0, 4 * noise / math.sqrt(len(speeds)))
    if moving:
        what = f"{drift:.3f} rev in {elapsed:.1f} s" if drift is not None else f"{mean:.0f} rpm"
        raise UsageError(f"refusing to move: the axis is moving with the servo off ({what}); a load torque "
                         "(gravity?) turns it and no brake holds it: secure the axis first")
    return rest


@dataclass
class Trace:
    t: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    torque: list[float] = field(default_factory=list)
    position: list[float | None] = field(default_factory=list)   # None where position was not read
    # When speed and torque cannot share one request (SD25 reads at most 10 registers), the speed is read a
    # request earlier: its own times, to bring it onto the torque's time base before the fit.
    speed_t: list[float] = field(default_factory=list)

    def aligned_speed(self) -> list[float]:
        """Speed at the torque's sample times (linear between speed reads); the speed itself if read together."""
        if len(self.speed_t) != len(self.t) or len(self.t) < 2:
            return list(self.speed)
        return [float(v) for v in np.interp(self.t, self.speed_t, self.speed)]

    def save(self, path: Path) -> None:
        try:
            with path.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["t_s", "speed_rpm", "torque_pct", "position_rev"])
                for t, v, q, x in zip(self.t, self.speed, self.torque, self.position, strict=True):
                    w.writerow([f"{t:.5f}", f"{v:.2f}", f"{q:.2f}", "" if x is None else f"{x:.4f}"])
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror}") from None


@dataclass
class Result:
    method: str
    old_ratio: float | None     # None: the profile maps no inertia-ratio parameter
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

    def __init__(self, message: str, result: Result) -> None:
        super().__init__(message)
        self.result = result


class Identifier:
    """Runs the identification motion on one drive."""

    def __init__(self, drive: Drive, timing: Timing | None = None, keepalive_s: float | None = None) -> None:
        self.drive = drive
        self.p = drive.profile
        self.timing = timing or RealTiming()
        self.keepalive_s = keepalive_s
        self.trace = Trace()    # filled while the motion runs; kept when it fails

    def _eng(self, entry: Entry) -> float:
        return float(raw_to_eng(entry, self.drive.read_entries([entry])[0].raw))

    def current_ratio(self) -> float | None:
        """The drive's configured load ratio; None where the profile maps no inertia-ratio parameter."""
        entry = self.p.role("inertia_ratio")
        return self.p.load_ratio_from_param(self._eng(entry)) if entry is not None else None

    # ----- host method ---------------------------------------------------------------------------------------
    def run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None = None,
                 rest: RestCheck | None = None) -> Result:
        """Pilot cycle, then the planned cycles; fit; raise IdentificationRefused when the fit is refused.

        The motion's own writes (speed, ramp) stay out of EEPROM where the drive has a switch."""
        with ram_writes(self.drive):
            return self._run_host(plan, progress, rest)

    def _run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None,
                  rest: RestCheck | None) -> Result:
        p, d = self.p, self.drive
        beat_s = self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d)
        jogger = Jogger(d, beat_s, FEATURE)
        jog_accel = p.need_role("jog_accel", FEATURE)
        saved = _motion_settings(d, jogger)
        speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
        pos_e = p.role("position_feedback")
        motor = p.motor
        assert motor is not None
        limit_e = p.role("torque_limit_fwd")
        torque_limit = self._eng(limit_e) if limit_e is not None else None
        written = dict(saved)
        old_ratio = self.current_ratio()
        noise = rest.speed_noise_rpm if rest is not None else 0.0
        stop_band = max(3.0, 4.0 * noise)
        trace = self.trace = Trace()
        t0 = self.timing.now()
        counts = motor.counts_per_rev
        state = {"last_beat": t0, "pos": None, "pos_t": t0, "lo": 0.0, "hi": 0.0,
                 "pred": 0.0}
        guard: dict[str, float | None] = {"lo": None, "hi": None, "stretch": 1.0}
        pos_every = 0.05   # position costs a request of its own: read it at 20 Hz, predict from speed between

        def set_param(entry: Entry, eng: float) -> None:
            raw = max(entry.min, min(entry.max, round(eng / entry.scale)))
            if written[entry.code] != raw:
                d.write_raw(entry, raw)
                written[entry.code] = raw

        def command(direction: int) -> None:
            jogger.command(direction)
            state["last_beat"] = self.timing.now()

        together = len(plan_reads(p, [speed_e, torque_e])) == 1     # one request carries both

        def sample() -> None:
            if together:
                readings = d.read_entries([speed_e, torque_e])
            else:
                readings = d.read_entries([speed_e])
                trace.speed_t.append(self.timing.now() - t0)
                readings += d.read_entries([torque_e])
            now = self.timing.now()
            speed = float(raw_to_eng(speed_e, readings[0].raw))
            if trace.t:   # travel between position reads, from the speed (checked before it is reached)
                state["pred"] += 0.5 * (speed + trace.speed[-1]) / 60.0 * (now - t0 - trace.t[-1])
            trace.t.append(now - t0)
            trace.speed.append(speed)
            trace.torque.append(float(raw_to_eng(torque_e, readings[1].raw)))
            trace.position.append(None)
            if pos_e is not None and (state["pos"] is None or now - state["pos_t"] >= pos_every):
                x = d.read_entries([pos_e])[0].raw / counts
                trace.position[-1] = x
                state["pos"], state["pos_t"], state["pred"] = x, self.timing.now(), x
                state["lo"] = min(state["lo"], x) if len(trace.t) > 1 else x
                state["hi"] = max(state["hi"], x) if len(trace.t) > 1 else x
            # Travel from the position reads, predicted from the speed between them (from the speed alone where
            # the profile has no usable position feedback).
            x = state["pred"]
            state["lo"], state["hi"] = min(state["lo"], x), max(state["hi"], x)
            if state["hi"] - state["lo"] > plan.travel_limit_rev:
                raise TravelExceeded(f"travel limit {plan.travel_limit_rev:g} rev reached: motion stopped; the "
                                     "loop overshoots (inertia ratio far off?): lower --max-speed or raise --travel")
            if self.timing.now() - state["last_beat"] >= beat_s:
                jogger.beat()
                state["last_beat"] = self.timing.now()

        ramp = plan.ramp_s

        def move(direction: int, speed: float) -> tuple[float, float]:
            """One accelerate-then-stop move; returns (excursion so far in rev, peak |torque| in %)."""
            first = len(trace.t)
            jogger.set_speed(speed)
            set_param(jog_accel, ramp * 1000.0 * motor.rated_speed_rpm / speed)
            command(direction)
            start = self.timing.now()
            while self.timing.now() - start < ramp:   # the drive's ramp reaches the speed in ramp_s
                sample()
                if guard["lo"] is not None:
                    # Stop early where the stopping distance (the ramp's, stretched as the pilot showed) would
                    # carry the axis out of its band: drift (gravity, overshoot) must not add up to the limit.
                    v = abs(trace.speed[-1])
                    stop_rev = guard["stretch"] * v * v * ramp / (2 * speed) / 60.0
                    # ... plus the travel until the stop command can act: the next sample and the write
                    stop_rev += v / 60.0 * 2.0 * (trace.t[-1] - trace.t[-2] if len(trace.t) > 1 else 0.0)
                    if (state["pred"] + stop_rev > guard["hi"]) if direction > 0 else \
                            (state["pred"] - stop_rev < guard["lo"]):
                        break
            command(0)
            stop = self.timing.now()
            while self.timing.now() - stop < 3 * ramp + 0.5:
                sample()
                if self.timing.now() - stop >= ramp and abs(trace.speed[-1]) < stop_band:
                    break
            sample()
            sample()                      # two samples at rest separate this move from the next
            active = active_alarm(d)
            if active:
                raise IdentificationFailed(f"the drive stopped the identification with alarm {active}")
            peak = max((abs(q) for q in trace.torque[first:]), default=0.0)
            return state["hi"] - state["lo"], peak

        both = len(plan.directions) > 1
        settings = EstimatorSettings(fit_load_torque=both)
        est: InertiaEstimate | None = None
        cycles = 0
        try:
            # Pilot cycle at reduced speed: how far the axis really goes per nominal revolution (a badly matched
            # speed loop overshoots) and how much torque the acceleration takes, before the full test.
            pilot = plan.speed_rpm * PILOT_SHARE
            if progress:
                progress(f"pilot move at {pilot:.0f} rpm")
            excursion, peak = 0.0, 0.0
            sample()                      # the axis's real position: the travel band is around it, not around 0
            origin = state["pred"]
            for direction in plan.directions:
                excursion, pk = move(direction, pilot)
                peak = max(peak, pk)
            nominal = pilot / 60.0 * plan.ramp_s * (1 if both else len(plan.directions))
            limit_rev = plan.travel_limit_rev
            lo = origin - 0.05 * limit_rev if both or plan.directions[0] > 0 else origin - 0.9 * limit_rev
            guard.update(lo=lo, hi=lo + 0.9 * limit_rev, stretch=max(1.0, excursion / nominal))
            # Excursion and torque grow in proportion to the speed at a fixed ramp time.
            speed = plan.speed_rpm
            stretch = float(guard["stretch"] or 1.0)
            if stretch > 1.5:
                # The loop cannot follow the ramps (far-off inertia ratio: an under-damped loop): slower ramps at
                # a lower speed (the same travel) keep its swing inside the travel band.
                factor = min(2.0, stretch / 1.5, 0.5 / ramp)
                ramp, speed = ramp * factor, speed / factor
                guard["stretch"] = stretch / factor
            if excursion > 0:
                room = 0.85 * plan.travel_limit_rev - (excursion if not both else 0.0)
                speed = min(speed, pilot * plan.ramp_s / ramp * room / (excursion * (plan.repeats if not both else 1)))
            if torque_limit is not None and peak > 0:
                speed = min(speed, pilot * TORQUE_SHARE * torque_limit / peak)
            cycle_s = (self.timing.now() - t0) * 1.1
            for rep in range(plan.repeats):
                if plan.adaptive and rep >= 2:
                    if self.timing.now() - t0 + cycle_s > TIME_BUDGET_S:
                        break
                    est = self._estimate(settings, torque_limit, rate=len(trace.t) / (self.timing.now() - t0))
                    if est.ok and est.j_std_kgm2 <= 0.5 * settings.max_rel_uncertainty * est.j_total_kgm2:
                        break
                for direction in plan.directions:
                    if progress:
                        progress(f"move {rep + 1}/{plan.repeats} {'forward' if direction > 0 else 'reverse'} "
                                 f"at {speed:.0f} rpm")
                    move(direction, speed)
                cycles += 1
        except BaseException:
            _stop_quietly(jogger)
            raise
        finally:
            _leave_and_restore(d, jogger, saved)
        elapsed = self.timing.now() - t0
        rate = (len(trace.t) - 1) / elapsed if elapsed > 0 else 0.0
        est = self._estimate(settings, torque_limit, rate)
        result = Result("host", old_ratio, est.load_ratio, est, trace, plan, state["hi"] - state["lo"], elapsed,
                        rate, cycles)
        if not est.ok:
            raise IdentificationRefused(f"identification refused: {est.reason}", result)
        return result

    def _estimate(self, settings: EstimatorSettings, torque_limit: float | None, rate: float) -> InertiaEstimate:
        motor = self.p.motor
        assert motor is not None
        # Fast links give many samples per ramp: allow windows long enough to span ~1/5 s.
        cfg = replace(settings, max_window_intervals=max(6, int(rate / 5)))
        return estimate_inertia(self.trace.t, self.trace.aligned_speed(), self.trace.torque,
                                rated_torque_nm=motor.rated_torque_nm, rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
                                torque_limit_pct=torque_limit, settings=cfg)

    # ----- drive method --------------------------------------------------------------------------------------
    def run_drive(self, timeout_s: float = 30.0, keep: bool = True) -> Result:
        """Trigger the drive's own identification, wait for it, read the inertia ratio it stored.

        The drive stores its result itself; keep=False (dry run) puts the previous value back afterwards.
        """
        p, d = self.p, self.drive
        ratio_e = p.need_role("inertia_ratio", FEATURE)
        old_raw = d.read_entries([ratio_e])[0].raw
        old = p.load_ratio_from_param(float(raw_to_eng(ratio_e, old_raw)))
        beat_s = self.keepalive_s if self.keepalive_s is not None else keepalive_interval_s(d)
        keepalive = p.role("keepalive")
        t0 = self.timing.now()
        d.trigger("inertia_id", FEATURE)
        status = p.role("servo_status")
        ident_bit = status_bit(status, "identifying") if status is not None else None
        try:
            while self.timing.now() - t0 < timeout_s:
                self.timing.sleep(min(0.1, beat_s))
                if keepalive is not None:
                    d.write_raw(keepalive, 1)
                if status is None or ident_bit is None:
                    continue
                if not d.read_entries([status])[0].raw >> ident_bit & 1:
                    break
            else:
                raise IdentificationFailed(f"the drive's identification did not finish within {timeout_s:g} s")
        except BaseException:
            try:
                d.trigger("inertia_id", FEATURE, 0)
            except ServoError:
                pass  # the drive's watchdog stops it
            raise
        active = active_alarm(d)
        if active:
            raise IdentificationFailed(f"the drive stopped its identification with alarm {active}")
        new_raw = d.read_entries([ratio_e])[0].raw
        new = p.load_ratio_from_param(float(raw_to_eng(ratio_e, new_raw)))
        if not keep and new_raw != old_raw:
            d.write_verified(ratio_e, old_raw)
        return Result("drive", old, new, None, Trace(), None, None, self.timing.now() - t0, 0.0)


@dataclass(frozen=True)
class GainChange:
    role: str
    entry: Entry
    old: float
    new: float
    raw: int


def gain_changes(drive: Drive, load_ratio: float, *, rigidity: int | None, bandwidth_hz: float | None
                 ) -> tuple[GainSuggestion, list[GainChange]]:
    """Gains for the identified inertia, mapped onto the profile's gain roles (clamped to their ranges)."""
    p = drive.profile
    motor = p.motor
    assert motor is not None
    if rigidity is None and bandwidth_hz is None:
        rig = p.role("rigidity")
        rigidity = int(raw_to_eng(rig, drive.read_entries([rig])[0].raw)) if rig else 13
        rigidity = max(1, min(31, rigidity))
    try:
        sugg = suggest_gains(rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2, load_ratio=max(0.0, load_ratio),
                             rigidity=rigidity, bandwidth_hz=bandwidth_hz)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    entries = [(role, p.role(role)) for role in GAIN_ROLES]
    present = [(role, e) for role, e in entries if e is not None]
    current = drive.read_entries([e for _, e in present])
    changes = []
    for (role, e), reading in zip(present, current, strict=True):
        target = from_canonical(role, e, getattr(sugg, GAIN_ROLES[role]))
        raw = max(e.min, min(e.max, round(target / e.scale)))
        changes.append(GainChange(role, e, float(raw_to_eng(e, reading.raw)), float(raw_to_eng(e, raw)), raw))
    return sugg, changes


def ratio_raw(drive: Drive, load_ratio: float) -> tuple[Entry, int]:
    entry = drive.profile.need_role("inertia_ratio", FEATURE)
    raw = round(drive.profile.param_from_load_ratio(max(0.0, load_ratio)) / entry.scale)
    if not entry.min <= raw <= entry.max:
        raise IdentificationFailed(f"identified ratio {load_ratio:.2f} does not fit {entry.code}'s range")
    return entry, raw


@dataclass(frozen=True)
class StepResponse:
    """Speed step through JOG with the shortest ramp the drive allows."""

    target_rpm: float
    overshoot_pct: float
    settling_ms: float | None     # within 5 % of the target for good; None when it never settles
    samples: int

    def describe(self) -> str:
        settle = f"{self.settling_ms:.0f} ms" if self.settling_ms is not None else "does not settle"
        return f"{self.target_rpm:.0f} rpm step: overshoot {self.overshoot_pct:.1f} %, settling (5 %) {settle}"


STEP_SPEED_RPM = 200.0


def step_duration_s(travel_rev: float, speed_rpm: float = STEP_SPEED_RPM) -> float:
    """How long the step check may run at speed_rpm inside the travel limit (it returns to where it started)."""
    duration = min(0.6, 0.9 * travel_rev / (1.3 * speed_rpm / 60.0))   # 30 % for overshoot and the stop
    if duration < 0.2:
        raise UsageError(f"--step-check needs at least {1.3 * speed_rpm / 60.0 * 0.2 / 0.9:.2f} rev of --travel "
                         f"for a {speed_rpm:g} rpm step")
    return duration


def _motion_settings(drive: Drive, jogger: Jogger) -> dict[str, int]:
    """Raw values of the settings a motion changes and puts back: the ramp, and a trigger route's JOG speed (a
    speed reference is put back by the jogger)."""
    entries = [drive.profile.need_role("jog_accel", FEATURE)]
    if jogger.route.kind == "trigger":
        entries.insert(0, jogger.speed_entry)
    return {e.code: r.raw for e, r in zip(entries, drive.read_entries(entries), strict=True)}


def _stop_quietly(jogger: Jogger) -> None:
    """Command stop after a failure; if the link is gone, the drive's watchdog stops the motor."""
    try:
        jogger.command(0)
    except ServoError:
        pass


def _leave_and_restore(drive: Drive, jogger: Jogger, saved: dict[str, int]) -> None:
    """Servo off and the motion settings put back (saved: code -> raw); a failure here never hides the first one."""
    try:
        jogger.leave()
        for code, raw in saved.items():
            entry = drive.profile.entry(code)
            if drive.read_entries([entry])[0].raw != raw:
                drive.write_raw(entry, raw)
    except ServoError:
        pass


def step_response(drive: Drive, speed_rpm: float, duration_s: float = 0.6, timing: Timing | None = None
                  ) -> StepResponse:
    """Command a JOG speed step forward, sample the speed, then the same step back to where it started.

    JOG parameters are put back afterwards (their writes kept out of EEPROM where the drive has a switch); the
    keep-alive beats at the drive's watchdog rate.
    """
    with ram_writes(drive):
        return _step_response(drive, speed_rpm, duration_s, timing)


def _step_response(drive: Drive, speed_rpm: float, duration_s: float, timing: Timing | None) -> StepResponse:
    p, timing = drive.profile, timing or RealTiming()
    beat_s = keepalive_interval_s(drive)
    jogger = Jogger(drive, beat_s, FEATURE)
    jog_accel = p.need_role("jog_accel", FEATURE)
    speed_e = p.need_role("speed_feedback", FEATURE)
    saved = _motion_settings(drive, jogger)
    t: list[float] = []
    v: list[float] = []
    last_beat = timing.now()

    def speed() -> float:
        nonlocal last_beat
        value = float(raw_to_eng(speed_e, drive.read_entries([speed_e])[0].raw))
        if timing.now() - last_beat >= beat_s:
            jogger.beat()
            last_beat = timing.now()
        return value

    def stop() -> None:
        jogger.command(0)
        end = timing.now() + 2.0
        while timing.now() < end and abs(speed()) > 3:
            timing.sleep(0.02)

    try:
        jogger.set_speed(speed_rpm)
        drive.write_raw(jog_accel, jog_accel.min)
        for direction in (1, -1):
            t0 = timing.now()
            jogger.command(direction)
            last_beat = t0
            while timing.now() - t0 < duration_s:
                now = timing.now() - t0
                value = speed()
                if direction > 0:
                    t.append(now)
                    v.append(value)
            stop()
        active = active_alarm(drive)
        if active:
            raise IdentificationFailed(f"the drive stopped the step check with alarm {active}")
    except BaseException:
        _stop_quietly(jogger)
        raise
    finally:
        _leave_and_restore(drive, jogger, saved)
    band = 0.05 * speed_rpm  # 5 %: a 2 % band sits inside typical speed-reading noise
    outside = [i for i, x in enumerate(v) if abs(x - speed_rpm) > band]
    settled = None if not v or (outside and outside[-1] == len(v) - 1) else \
        (t[outside[-1] + 1] if outside else t[0]) * 1000
    return StepResponse(speed_rpm, max(0.0, (max(v, default=0.0) - speed_rpm) / speed_rpm * 100), settled, len(v))
