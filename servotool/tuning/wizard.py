"""Inertia identification wizard: pre-checks, a bounded back-and-forth JOG motion with sampling, estimation, result.

Host method: speed-controlled moves through the profile's JOG roles with the same dead-man keep-alive as `jog`,
speed and torque sampled over Modbus, then the integral-form fit of servotool.tuning.estimator.
Drive method: triggers the profile's drive-side identification (role inertia_id) and reads its result.
"""

from __future__ import annotations

import csv
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

from servotool import alarms
from servotool.codec import raw_to_eng
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.motion import Jogger, motion_route, servo_is_on
from servotool.profile import Entry, Profile
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


@dataclass(frozen=True)
class MotionPlan:
    speed_rpm: float
    ramp_s: float            # time to reach speed (and to stop)
    directions: tuple[int, ...]
    repeats: int
    travel_limit_rev: float

    @property
    def move_travel_rev(self) -> float:
        """Travel of one accelerate-then-stop move (triangular speed profile)."""
        return self.speed_rpm / 60.0 * self.ramp_s

    @property
    def excursion_rev(self) -> float:
        """Range of positions covered: one move each way (both directions), or all moves (one direction)."""
        return self.move_travel_rev * (len(self.directions) if len(self.directions) > 1 else self.repeats)

    @property
    def duration_s(self) -> float:
        return len(self.directions) * self.repeats * (2 * self.ramp_s + 0.15)

    def describe(self) -> str:
        names = {1: "forward", -1: "reverse"}
        seq = " then ".join(names[d] for d in self.directions)
        return (f"{self.repeats} x ({seq}) moves to {self.speed_rpm:.0f} rpm, {self.ramp_s * 1000:.0f} ms ramps, "
                f"{self.move_travel_rev:.2f} rev per move, {self.excursion_rev:.2f} rev of travel in all "
                f"(limit {self.travel_limit_rev:g} rev), about {self.duration_s:.1f} s")


def plan_motion(profile: Profile, *, max_speed: float | None, accel_time_ms: float | None, travel_rev: float,
                direction: str, repeats: int) -> MotionPlan:
    """Choose speed and ramp so each move stays inside the travel limit; refuse what cannot."""
    if travel_rev <= 0:
        raise UsageError("--travel must be > 0 revolutions")
    if repeats < 1 or repeats > 20:
        raise UsageError("--repeats must be 1..20")
    dirs = {"both": (1, -1), "forward": (1,), "reverse": (-1,)}.get(direction)
    if dirs is None:
        raise UsageError("--direction must be both, forward or reverse")
    ramp = (accel_time_ms or 200.0) / 1000.0
    if not 0.02 <= ramp <= 5.0:
        raise UsageError("--accel-time must be 20..5000 ms")
    # Moves go out and back, so the range covered is one move per direction; keep a margin for overshoot.
    budget = 0.9 * travel_rev / (len(dirs) if len(dirs) > 1 else repeats)
    speed = budget / ramp * 60.0
    motor = profile.motor
    limit = motor.rated_speed_rpm if motor else 3000.0
    if max_speed is not None:
        if max_speed <= 0:
            raise UsageError("--max-speed must be > 0")
        limit = min(limit, max_speed)
    speed = min(speed, limit)
    plan = MotionPlan(speed, ramp, dirs, repeats, travel_rev)
    if speed < 30.0:
        raise UsageError(f"travel limit {travel_rev:g} rev is too small for an identification with "
                         f"{ramp * 1000:.0f} ms ramps (needs at least {30 / 60 * ramp / 0.75:.2f} rev per move); "
                         "raise --travel or shorten --accel-time")
    if plan.excursion_rev > travel_rev:
        raise UsageError(f"the motion needs {plan.excursion_rev:.2f} rev, over the --travel limit {travel_rev:g}")
    return plan


def preflight(drive: Drive, method: str) -> None:
    """Link, roles, alarm and servo state; raises with one clear line."""
    p = drive.profile
    need = ["speed_feedback", "torque_feedback", "inertia_ratio"]
    need += ["jog_accel"] if method == "host" else ["inertia_id"]
    for role in need:
        p.need_role(role, f"{FEATURE} --method {method}")
    if method == "host":
        motion_route(p, f"{FEATURE} --method {method}")   # a JOG trigger or speed reference + servo-on
    if p.motor is None:
        raise UsageError(f"{FEATURE} needs the motor data (rated torque, rotor inertia) in profile {p.id}")
    if p.role("alarm_code") is not None:
        state = alarms.current(drive)
        if state.active:
            raise UsageError(f"refusing to move: alarm {state.display} {state.name} is active (clear it first)")
    if servo_is_on(drive):
        raise UsageError("refusing to move: the servo is on (enabled from elsewhere); switch it off first")


@dataclass
class Trace:
    t: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    torque: list[float] = field(default_factory=list)
    position: list[float] = field(default_factory=list)

    def save(self, path: Path) -> None:
        try:
            with path.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["t_s", "speed_rpm", "torque_pct", "position_rev"])
                for row in zip(self.t, self.speed, self.torque, self.position, strict=True):
                    w.writerow([f"{row[0]:.5f}", f"{row[1]:.2f}", f"{row[2]:.2f}", f"{row[3]:.4f}"])
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror}") from None


@dataclass
class Result:
    method: str
    old_ratio: float
    new_ratio: float
    estimate: InertiaEstimate | None
    trace: Trace
    plan: MotionPlan | None
    travel_used_rev: float
    time_used_s: float
    samples_per_s: float


class Identifier:
    """Runs the identification motion on one drive."""

    def __init__(self, drive: Drive, timing: Timing | None = None, keepalive_s: float = 0.1) -> None:
        self.drive = drive
        self.p = drive.profile
        self.timing = timing or RealTiming()
        self.keepalive_s = keepalive_s

    def _eng(self, entry: Entry) -> float:
        return float(raw_to_eng(entry, self.drive.read_entries([entry])[0].raw))

    def current_ratio(self) -> float:
        return self.p.load_ratio_from_param(self._eng(self.p.need_role("inertia_ratio", FEATURE)))

    # ----- host method ---------------------------------------------------------------------------------------
    def run_host(self, plan: MotionPlan, progress: Callable[[str], None] | None = None) -> Result:
        p, d = self.p, self.drive
        jogger = Jogger(d, self.keepalive_s, FEATURE)
        jog_speed, jog_accel = jogger.speed_entry, p.need_role("jog_accel", FEATURE)
        speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
        pos_e = p.role("position_feedback")
        sampled = [speed_e, torque_e] + ([pos_e] if pos_e else [])
        saved = {e.code: r.raw for e, r in zip((jog_speed, jog_accel), d.read_entries([jog_speed, jog_accel]),
                                                  strict=True)}
        old_ratio = self.current_ratio()
        motor = p.motor
        assert motor is not None
        trace = Trace()
        t0 = self.timing.now()
        counts = motor.counts_per_rev
        beat = [0, t0]

        def sample() -> None:
            readings = d.read_entries(sampled)
            trace.t.append(self.timing.now() - t0)
            trace.speed.append(float(raw_to_eng(speed_e, readings[0].raw)))
            trace.torque.append(float(raw_to_eng(torque_e, readings[1].raw)))
            trace.position.append(readings[2].raw / counts if pos_e else math.nan)
            if pos_e and max(trace.position) - min(trace.position) > plan.travel_limit_rev:
                raise TravelExceeded(f"travel limit {plan.travel_limit_rev:g} rev reached: motion stopped; the "
                                     "loop overshoots (inertia ratio far off?): lower --max-speed or raise --travel")
            if self.timing.now() - beat[1] >= self.keepalive_s:
                jogger.beat()
                beat[1] = self.timing.now()

        def wait_until(cond: Callable[[], bool], limit_s: float) -> None:
            end = self.timing.now() + limit_s
            while self.timing.now() < end:
                sample()
                if cond():
                    return

        def move(direction: int, speed: float) -> float:
            """One accelerate-then-stop move; returns the largest excursion seen so far (rev)."""
            jogger.set_speed(speed)
            self._set(jog_accel, plan.ramp_s * 1000.0 * motor.rated_speed_rpm / speed)
            jogger.command(direction)
            wait_until(lambda: False, plan.ramp_s)   # the drive's ramp reaches the speed in ramp_s
            jogger.command(0)
            wait_until(lambda: abs(trace.speed[-1]) < 2.0, plan.ramp_s * 3 + 0.5)
            wait_until(lambda: False, 0.1)
            pos = [x for x in trace.position if not math.isnan(x)]
            return max(pos) - min(pos) if pos else 0.0

        try:
            # Pilot moves at half speed: a badly matched speed loop overshoots, so measure how far the axis
            # really goes per nominal revolution before committing to the full speed.
            speed = plan.speed_rpm
            if pos_e is not None:
                pilot = plan.speed_rpm / 2
                if progress:
                    progress(f"pilot moves at {pilot:.0f} rpm")
                excursion = max(move(direction, pilot) for direction in plan.directions)
                nominal = pilot / 60.0 * plan.ramp_s * len(plan.directions)
                factor = max(1.0, excursion / nominal) if nominal > 0 else 1.0
                speed = min(speed, plan.speed_rpm / factor)
            for rep in range(plan.repeats):
                for direction in plan.directions:
                    if progress:
                        progress(f"move {rep + 1}/{plan.repeats} {'forward' if direction > 0 else 'reverse'} "
                                 f"at {speed:.0f} rpm")
                    move(direction, speed)
        except BaseException:
            try:
                jogger.command(0)
            except ServoError:
                pass  # the drive's watchdog stops it
            raise
        finally:
            jogger.leave()
            for e in (jog_speed, jog_accel):
                if d.read_entries([e])[0].raw != saved[e.code]:
                    d.write_raw(e, saved[e.code])
        elapsed = self.timing.now() - t0
        limit = p.role("torque_limit_fwd")
        rate = (len(trace.t) - 1) / elapsed if elapsed > 0 else 0.0
        # Fast links give many samples per ramp: allow windows long enough to span ~1/5 s.
        settings = EstimatorSettings(max_window_intervals=max(6, int(rate / 5)))
        est = estimate_inertia(trace.t, trace.speed, trace.torque, rated_torque_nm=motor.rated_torque_nm,
                               rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
                               torque_limit_pct=self._eng(limit) if limit is not None else None, settings=settings)
        pos = [x for x in trace.position if not math.isnan(x)]
        travel = (max(pos) - min(pos)) if pos else plan.excursion_rev
        result = Result("host", old_ratio, est.load_ratio, est, trace, plan, travel, elapsed, rate)
        if not est.ok:
            raise IdentificationFailed(f"identification refused: {est.reason}", ) from None
        return result

    def _set(self, entry: Entry, eng: float) -> None:
        raw = max(entry.min, min(entry.max, round(eng / entry.scale)))
        if self.drive.read_entries([entry])[0].raw != raw:
            self.drive.write_raw(entry, raw)

    # ----- drive method --------------------------------------------------------------------------------------
    def run_drive(self, timeout_s: float = 30.0) -> Result:
        """Trigger the drive's own identification, wait for it, read the inertia ratio it stored."""
        old = self.current_ratio()
        t0 = self.timing.now()
        self.drive.trigger("inertia_id", FEATURE)
        status = self.p.role("servo_status")
        ident_bit = next((b for b, n in (status.bits.items() if status else []) if n == "identifying"), None)
        while self.timing.now() - t0 < timeout_s:
            self.timing.sleep(0.1)
            if self.p.role("keepalive") is not None:
                self.drive.write_raw(self.p.role("keepalive"), 1)  # type: ignore[arg-type]
            if status is None or ident_bit is None:
                continue
            if not self.drive.read_entries([status])[0].raw >> ident_bit & 1:
                break
        else:
            self.drive.trigger("inertia_id", FEATURE, 0)
            raise IdentificationFailed(f"the drive's identification did not finish within {timeout_s:g} s")
        if self.p.role("alarm_code") is not None:
            state = alarms.current(self.drive)
            if state.active:
                raise IdentificationFailed(f"the drive reports {state.display} {state.name}")
        new = self.current_ratio()
        return Result("drive", old, new, None, Trace(), None, math.nan, self.timing.now() - t0, 0.0)


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
        target = getattr(sugg, GAIN_ROLES[role])
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


def step_response(drive: Drive, speed_rpm: float, duration_s: float = 0.6, timing: Timing | None = None
                  ) -> StepResponse:
    """Command a JOG speed step, sample the speed, stop; JOG parameters are put back afterwards."""
    p, timing = drive.profile, timing or RealTiming()
    jogger = Jogger(drive, feature=FEATURE)
    jog_speed, jog_accel = jogger.speed_entry, p.need_role("jog_accel", FEATURE)
    speed_e = p.need_role("speed_feedback", FEATURE)
    saved = {e.code: r.raw for e, r in zip((jog_speed, jog_accel), drive.read_entries([jog_speed, jog_accel]),
                                              strict=True)}
    t: list[float] = []
    v: list[float] = []
    try:
        jogger.set_speed(speed_rpm)
        drive.write_raw(jog_accel, jog_accel.min)
        t0 = timing.now()
        jogger.command(1)
        last_beat = t0
        while timing.now() - t0 < duration_s:
            t.append(timing.now() - t0)
            v.append(float(raw_to_eng(speed_e, drive.read_entries([speed_e])[0].raw)))
            if timing.now() - last_beat > 0.1:
                jogger.beat()
                last_beat = timing.now()
        jogger.command(0)
        end = timing.now() + 2.0
        while timing.now() < end and abs(float(raw_to_eng(speed_e, drive.read_entries([speed_e])[0].raw))) > 3:
            timing.sleep(0.02)
            jogger.beat()
    finally:
        jogger.leave()
        for e in (jog_speed, jog_accel):
            drive.write_raw(e, saved[e.code])
    band = 0.05 * speed_rpm  # 5 %: a 2 % band sits inside typical speed-reading noise
    outside = [i for i, x in enumerate(v) if abs(x - speed_rpm) > band]
    settled = None if not v or (outside and outside[-1] == len(v) - 1) else \
        (t[outside[-1] + 1] if outside else t[0]) * 1000
    return StepResponse(speed_rpm, max(0.0, (max(v, default=0.0) - speed_rpm) / speed_rpm * 100), settled, len(v))
