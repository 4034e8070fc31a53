"""A speed step response to check the tuned loop: overshoot and settling."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.quantity import quantity
from servotool.motion import deadman
from servotool.motion.deadman import DeadManBound
from servotool.motion.keepalive import keepalive_interval_s
from servotool.motion.moves import Mover
from servotool.tuning.errors import IdentificationFailed
from servotool.tuning.gain_writes import drive_loop
from servotool.tuning.preflight import FEATURE, active_alarm
from servotool.tuning.stable_hold import StableHold

OVERSHOOT_LIMIT_PCT = 35.0  # a PI speed loop at 45 degrees of phase margin overshoots a fast step by about 30 %


@dataclass(frozen=True)
class StepResponse:
    """Speed step through JOG with the shortest ramp the drive allows. Times count from the moment the step command
    went out; the first sample is the speed at rest just before it, so every step starts from the same zero."""

    target_rpm: float
    overshoot_pct: float
    settling_ms: float | None  # within 5 % of the target for good; None when it never settles
    samples: int
    ripple_pct: float = 0.0  # speed's standard deviation over the second half, % of the target (ringing)
    t_s: tuple[float, ...] = field(default=(), repr=False)  # the forward step's samples, for its chart
    speed_rpm: tuple[float, ...] = field(default=(), repr=False)
    interval_ms: float = 0.0  # median time between speed samples (speed only, over the line)
    longest_gap_ms: float = 0.0
    command_ms: float = 0.0  # how long the step command took to send (the drive may start anywhere inside it)
    loop_hz: float | None = None  # the speed loop's gain while stepping (what the overshoot's length follows)

    def summary(self) -> dict[str, Any]:
        """The figures without the samples, each a value with its unit (model.quantity)."""

        def q(x: float | None, unit: str) -> dict[str, Any] | None:
            return quantity(None if x is None or not math.isfinite(x) else round(x, 2), unit)

        return {
            "target": q(self.target_rpm, "rpm"),
            "overshoot": q(self.overshoot_pct, "%"),
            "settling": q(self.settling_ms, "ms"),
            "samples": self.samples,
            "ripple": q(self.ripple_pct, "%"),
            "interval": q(self.interval_ms, "ms"),
            "longest_gap": q(self.longest_gap_ms, "ms"),
            "command": q(self.command_ms, "ms"),
            "overshoot_bound": q(self.overshoot_bound_pct, "%"),
        }

    @property
    def overshoot_ms(self) -> float | None:
        """About how long a speed loop at loop_hz stays over its target on a step: half a period at its gain."""
        return 1000.0 / (2.0 * self.loop_hz) if self.loop_hz else None

    @property
    def overshoot_bound_pct(self) -> float | None:
        """The most the overshoot can be, given the samples: a lobe of overshoot_ms sampled every interval_ms is
        caught at least cos(pi * interval / (2 * lobe)) of its height; None when samples may miss it altogether."""
        lobe = self.overshoot_ms
        if lobe is None:
            return self.overshoot_pct
        if self.interval_ms >= lobe:
            return None
        return self.overshoot_pct / math.cos(math.pi * self.interval_ms / (2.0 * lobe))

    @property
    def overshoot_visible(self) -> bool:
        """Whether the sampling is fine enough to bound the overshoot it judges."""
        return self.overshoot_bound_pct is not None

    def failure(self, overshoot_limit_pct: float = OVERSHOOT_LIMIT_PCT) -> str | None:
        """Why this response fails the check after writing gains (None: it passes). The overshoot judged is the
        most it can be between the samples; a step sampled too coarsely to bound it proves nothing and fails."""
        if self.settling_ms is None:
            return "the speed does not settle"
        bound = self.overshoot_bound_pct
        if bound is None:
            return (
                f"sampled every {self.interval_ms:.0f} ms, too coarse to see the overshoot of a "
                f"{self.loop_hz:.0f} Hz speed loop (about {self.overshoot_ms:.0f} ms long): not proven"
            )
        if bound > overshoot_limit_pct:
            if round(bound) == round(self.overshoot_pct):
                return f"overshoot {bound:.0f} % over the {overshoot_limit_pct:g} % limit"
            return (
                f"overshoot up to {bound:.0f} % (measured {self.overshoot_pct:.0f} %, sampled every "
                f"{self.interval_ms:.0f} ms) over the {overshoot_limit_pct:g} % limit"
            )
        if self.ripple_pct > RIPPLE_LIMIT_PCT:
            return f"the speed rings ({self.ripple_pct:.1f} % ripple at constant speed)"
        return None

    def sampling(self) -> str:
        """The check's sampling limit, in words."""
        gap = f", longest gap {self.longest_gap_ms:.0f} ms" if self.longest_gap_ms > 1.5 * self.interval_ms else ""
        return (
            f"sampled every {self.interval_ms:.0f} ms{gap} (speed only, over the line: no drive-side trace): an "
            "overshoot shorter than that may be missed"
        )

    def describe(self) -> str:
        settle = f"{self.settling_ms:.0f} ms" if self.settling_ms is not None else "does not settle"
        bound = self.overshoot_bound_pct
        over = f"{self.overshoot_pct:.1f} %" + (
            " (NOT RESOLVED at this sampling)"
            if bound is None
            else f" (up to {bound:.1f} % between samples)"
            if bound > self.overshoot_pct + 0.05
            else ""
        )
        return (
            f"{self.target_rpm:.0f} rpm step: overshoot {over}, settling (5 %) {settle}, ripple {self.ripple_pct:.1f} %"
        )


STEP_SPEED_RPM = 200.0
RIPPLE_LIMIT_PCT = 3.0  # a loop that keeps oscillating (torque at its limit) shows as ripple, often aliased


def step_duration_s(travel_rev: float, speed_rpm: float = STEP_SPEED_RPM) -> float:
    """How long the step check may run at speed_rpm inside the travel limit (it returns to where it started)."""
    duration = min(0.6, 0.9 * travel_rev / (1.3 * speed_rpm / 60.0))  # 30 % for overshoot and the stop
    if duration < 0.2:
        raise UsageError(
            f"--step-check needs at least {1.3 * speed_rpm / 60.0 * 0.2 / 0.9:.2f} rev of --travel "
            f"for a {speed_rpm:g} rpm step"
        )
    return duration


@dataclass(frozen=True)
class StepPlan:
    """A step check that fits its travel limit: its speed, how long each step runs, and what a dead host lets the
    motor run on (printed before moving)."""

    speed_rpm: float
    duration_s: float
    bound: DeadManBound

    def describe(self) -> str:
        lowered = "" if self.speed_rpm >= STEP_SPEED_RPM else " (lowered so that a dead host's run-on fits the travel)"
        return f"{self.speed_rpm:.0f} rpm{lowered} for {self.duration_s:.2f} s forward and back"


MIN_STEP_S = 0.2  # a step shorter than this shows no settling


def plan_step(drive: Drive, travel_rev: float) -> StepPlan:
    """The step check's speed and time: each step and what a dead host lets the motor run on from its end fit
    inside the travel limit (STEP_SPEED_RPM where they do, else lower; refused where not even 20 rpm fits)."""
    step_duration_s(travel_rev)  # the travel's own check, as before the drive is opened
    ramp = drive.profile.need_role("jog_accel", FEATURE)  # the check runs at its shortest ramp
    ramp_ms = float(raw_to_eng(ramp, ramp.min))
    beat = min(0.1, keepalive_interval_s(drive))
    timeout = deadman.drive_timeout_s(drive) if drive.profile.role("comm_timeout") is not None else None
    room = 0.9 * travel_rev

    def bound(speed: float, duration_s: float = MIN_STEP_S) -> DeadManBound:
        b = deadman.bound(drive, speed, beat, ramp_ms, drive.dead_man_waived, timeout)
        if b.route != "segment":
            return b
        # On the segment route each step is one segment of its own, ending where the step ends: that is its bound.
        return replace(b, stop_rev=speed / 60.0 * duration_s, stop_s=duration_s + (b.stop_s or 0.0) / 2.0)

    def run_on(speed: float) -> float:
        if bound(speed).route == "segment":
            return 0.0  # the step's own segment ends inside its travel
        return bound(speed).stop_rev or 0.0  # nothing bounds it (--no-dead-man): nothing to fit

    def fits(speed: float) -> bool:
        return 1.3 * speed / 60.0 * MIN_STEP_S + run_on(speed) <= room

    speed = deadman.largest_fitting_speed(STEP_SPEED_RPM, fits, 20.0)
    if speed is None:
        b = bound(STEP_SPEED_RPM)
        raise UsageError(
            f"--travel {travel_rev:g} leaves no room for a step check and what a dead host lets the motor run on "
            f"({run_on(STEP_SPEED_RPM):.2f} rev at {STEP_SPEED_RPM:g} rpm, {b.route}): give more --travel"
            + deadman.timeout_remedy(drive, b)
        )
    duration = min(0.6, (room - run_on(speed)) / (1.3 * speed / 60.0))
    b = bound(speed, duration)
    deadman.check(b, drive.dead_man_waived)
    return StepPlan(speed, duration, b)


@dataclass(frozen=True)
class Leg:
    """One leg of a step motion: samples from the moment its command went out (the first: at rest just before)."""

    direction: int
    ramp_ms: float  # the JOG ramp of this leg (time from 0 to rated speed)
    t: tuple[float, ...]
    speed_rpm: tuple[float, ...]
    torque_pct: tuple[float, ...]  # empty where the leg read no torque
    command_ms: float  # how long its command took to send


def step_response(
    drive: Drive, speed_rpm: float, duration_s: float = 0.6, timing: Clock | None = None, load_unknown: bool = False
) -> StepResponse:
    """Command a JOG speed step forward, sample the speed, then the same step back to where it started.

    However it ends, the motion's stop sequence stops the motor, puts the JOG parameters back (their writes kept out
    of EEPROM where the drive has a switch) and reads the drive back (motion/stop.py); the keep-alive beats at the
    drive's watchdog rate. load_unknown (the check before identification): on a route that
    holds position between the steps, the position gain is lowered meanwhile so that the hold cannot swing up on
    a load far above the configured ratio (tuning.stable_hold); the speed loop being checked is left as it is.
    """
    legs, loop_hz = step_legs(drive, speed_rpm, duration_s, timing, load_unknown=load_unknown)
    return _response(legs[0], speed_rpm, duration_s, loop_hz)


def step_legs(
    drive: Drive,
    speed_rpm: float,
    duration_s: float,
    timing: Clock | None = None,
    *,
    load_unknown: bool = False,
    back_ramp_ms: float | None = None,
    torque: bool = False,
) -> tuple[list[Leg], float | None]:
    """The step motion: forward at the shortest ramp for duration_s, stop, then back for as long (at back_ramp_ms,
    a trapezoid, where given: no farther, since a JOG stops at the ramp it starts with), stop; speed (and torque
    where asked, in the fewest requests) at the line's full rate. Returns the legs and the speed loop's gain. It
    ends through the motion's one stop sequence (step_response)."""
    p, timing = drive.profile, timing or RealClock()
    jogger = Mover(drive, keepalive_interval_s(drive), FEATURE, timing)
    # The drive's own protections for the step and back (it stays within the travel step_duration_s allowed it),
    # set inside the stop scope below before the first step.
    jogger.protect_for(speed_rpm, 1.3 * speed_rpm / 60.0 * duration_s / 0.9)
    jog_accel = p.need_role("jog_accel", FEATURE)
    speed_e = p.need_role("speed_feedback", FEATURE)
    read = [speed_e, p.need_role("torque_feedback", FEATURE)] if torque else [speed_e]
    loop_hz = drive_loop(drive).speed_hz
    legs: list[Leg] = []

    def sample() -> tuple[float, float | None]:
        readings = drive.read_entries(read)
        jogger.keep_alive()
        jogger.watch_inputs()
        values = [float(raw_to_eng(r.entry, r.raw)) for r in readings]
        return values[0], (values[1] if torque else None)

    def stop() -> None:
        jogger.command(0)
        end = timing.now() + 2.0
        while timing.now() < end and abs(sample()[0]) > 3:
            timing.sleep(0.02)

    with jogger.stopping(need_ramp=True) as saved:  # however the check ends: the one stop sequence
        if load_unknown:
            StableHold(drive, jogger.route.kind, saved).soften_position()
        if jogger.segments is not None:
            jogger.segments.single = True  # each step one segment of its own: its bound is the step (plan_step)
        jogger.set_speed(speed_rpm)  # the settings before the first step, so that its time counts from the command
        jogger.set_ramp(jog_accel.min)
        for direction in (1, -1):
            ramp_raw = jog_accel.min
            if direction < 0 and back_ramp_ms is not None:
                ramp_raw = eng_to_raw(jog_accel, back_ramp_ms)
            rest, rest_torque = sample()  # the same zero for every step: at rest, just before the command
            t, v, q = [0.0], [rest], [rest_torque]
            t0 = timing.now()
            jogger.start(direction, speed_rpm, ramp_raw, stop_after_s=duration_s)
            command_s = timing.now() - t0
            # nothing but the samples in this loop (the keep-alive only when due): the line's full rate
            while (now := timing.now() - t0) < duration_s:
                value, moment = sample()
                t.append(now)
                v.append(value)
                q.append(moment)
            stop()
            torques = tuple(float(x) for x in q if x is not None) if torque else ()
            ramp_ms = float(raw_to_eng(jog_accel, ramp_raw))
            legs.append(Leg(direction, ramp_ms, tuple(t), tuple(v), torques, command_s * 1000.0))
        active = active_alarm(drive)
        if active:
            gap = max((b - a for leg in legs for a, b in itertools.pairwise(leg.t)), default=0.0)
            raise IdentificationFailed(f"the drive stopped the step check with alarm {active}" + jogger.starved(gap))
    return legs, loop_hz


def _response(leg: Leg, speed_rpm: float, duration_s: float, loop_hz: float | None) -> StepResponse:
    """The forward leg's overshoot, settling and ripple."""
    t, v = list(leg.t), list(leg.speed_rpm)
    band = 0.05 * speed_rpm  # 5 %: a 2 % band sits inside typical speed-reading noise
    outside = [i for i, x in enumerate(v) if abs(x - speed_rpm) > band]
    settled = (
        None if not v or (outside and outside[-1] == len(v) - 1) else (t[outside[-1] + 1] if outside else t[0]) * 1000
    )
    late = [x for tt, x in zip(t, v, strict=True) if tt >= duration_s / 2]
    ripple = float(np.std(late)) / speed_rpm * 100 if len(late) > 2 else 0.0
    gaps = np.diff(np.asarray(t[1:])) * 1000.0  # between the samples taken after the command
    return StepResponse(
        speed_rpm,
        max(0.0, (max(v, default=0.0) - speed_rpm) / speed_rpm * 100),
        settled,
        len(v),
        ripple,
        tuple(t),
        tuple(v),
        interval_ms=float(np.median(gaps)) if gaps.size else duration_s * 1000.0,
        longest_gap_ms=float(np.max(gaps)) if gaps.size else duration_s * 1000.0,
        command_ms=leg.command_ms,
        loop_hz=loop_hz,
    )
