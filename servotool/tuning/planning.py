"""Planning host-driven identification motion: speed, ramps, travel and repeats from the line's sampling rate."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.profile import Profile
from servotool.motion import deadman
from servotool.motion.deadman import DeadManBound
from servotool.motion.keepalive import keepalive_interval_s
from servotool.tuning import budget
from servotool.tuning.budget import DITHER_MIN, Needs
from servotool.tuning.fit import EstimatorSettings
from servotool.tuning.preflight import DEFAULT_SAMPLES_PER_S, FEATURE, RestCheck, check_at_rest

# Automatic ramps last this many sampling intervals of the rest check (the motion samples about 2/3 as fast:
# position reads and keep-alives share the link). Fewer leave too few windows between torque steps and let the axis
# run further between two samples than the travel guard can foresee; more lower the acceleration (it falls with the
# square of the ramp time at a fixed travel), and a low-inertia axis with a noisy torque reading then cannot reach
# the precision within the time budget.
SAMPLES_PER_RAMP = 7.0
MIN_RAMP_S = 0.1  # ... and at least this long (a loop with factory gains on an unknown load follows them)


MIN_SPEED_RPM = 30.0  # no identification below this test speed

# Automatic repeats stop before the motion (with its pilot) would take longer than this, unless the line needs more
# (budget: MotionPlan.time_budget_s).
TIME_BUDGET_S = budget.MIN_TIME_S


# The pilot moves at this share of the planned speed: a badly matched speed loop can overshoot its travel
# several times over, and the pilot must stay inside the limit even then.
PILOT_SHARE = 0.25


# Where the torque reads in coarse steps, each cycle's acceleration is scaled by a different factor down to this
# (a shorter ramp at the same speed, or a lower speed where the ramp would get too few samples). The reading then
# misreads the acceleration torque by a different fraction of its step in every cycle instead of by the same
# amount: the step error averages out over the cycles and the move jackknife sees it, where with one acceleration
# it repeats identically and only a fixed floor (fit.quantization) can cover it.
COARSE_TORQUE_STEP_PCT = 0.5  # readings in steps this coarse (% of rated) are dithered
MIN_SAMPLES_PER_RAMP = 5.0  # a dithered ramp keeps this many sampling intervals (else the speed is lowered)
# ... and at least this long: below the planned ramps' floor, since on a fast line that floor, not the samples,
# bounds the ramp, and lowering the speed instead would weaken the accelerations of light loads whose acceleration
# torque is already near the reading's step; the planned ramps, which the pilot and the travel guard are learned
# with, keep their floor.
DITHER_MIN_RAMP_S = 0.05


def dither(cycle: int) -> float:
    """The ramp factor of a cycle: 1, then spread over [DITHER_MIN, 1] by halving the gaps (van der Corput)."""
    x, denom, n = 0.0, 1.0, cycle
    while n:
        denom *= 2.0
        x += (n & 1) / denom
        n >>= 1
    return 1.0 - (1.0 - DITHER_MIN) * x


def dithered(
    ramp_s: float, speed_rpm: float, cycle: int, samples_per_s: float, min_ramp_s: float = 0.0
) -> tuple[float, float]:
    """Ramp and speed of a dithered cycle: the ramp shortened by dither(cycle) (stronger, less travel) down to
    MIN_SAMPLES_PER_RAMP samples, DITHER_MIN_RAMP_S and min_ramp_s, below that the speed lowered (weaker; a ramp of
    fewer samples has no windows clear of its torque steps)."""
    floor = max(DITHER_MIN_RAMP_S, min_ramp_s, MIN_SAMPLES_PER_RAMP / samples_per_s if samples_per_s > 0 else 0.0)
    factor = dither(cycle)
    ramp = max(min(ramp_s, floor), ramp_s * factor)
    return ramp, speed_rpm * min(1.0, factor * ramp_s / ramp)


@dataclass(frozen=True)
class MotionPlan:
    speed_rpm: float
    ramp_s: float  # time to reach speed (and to stop)
    directions: tuple[int, ...]
    repeats: int  # move cycles; with `adaptive` the most that will run
    travel_limit_rev: float
    adaptive: bool = False  # stop repeating once the estimate is precise enough (and within time_budget_s)
    speed_limit_rpm: float = math.inf  # the motor's rated speed, or --max-speed below it
    time_budget_s: float = TIME_BUDGET_S  # adaptive repeats stop before the motion would take longer
    time_limit_s: float = budget.MAX_TIME_S  # said before moving (budget.Needs.most_s): no budget grows beyond it
    needs: Needs | None = None  # what the line needs for the fit's limit (both directions, automatic ramps)
    run_on_limited: bool = False  # the speed was lowered so that a dead host's run-on stays inside the travel
    travel_given: bool = False  # the user gave the travel (or chose the one named): the fit decides, not the pilot

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
        moves = len(self.directions) * (self.repeats + 1)  # + the pilot
        return min(moves * (2 * self.ramp_s + 0.1), self.time_budget_s if self.adaptive else math.inf)

    def budgeted(self, seconds: float) -> MotionPlan:
        """The adaptive plan with a time budget of `seconds` (at least TIME_BUDGET_S, at most the time limit said
        before moving), and the repeats to fill it."""
        if not self.adaptive:
            return self
        budget_s = min(self.time_limit_s, max(TIME_BUDGET_S, seconds))
        cycles = max(self.repeats, math.ceil(budget_s / (2 * (2 * self.ramp_s + 0.1))))
        return replace(self, time_budget_s=budget_s, repeats=cycles)

    def describe(self) -> str:
        names = {1: "forward", -1: "reverse"}
        seq = " then ".join(names[d] for d in self.directions)
        count = f"up to {self.repeats}" if self.adaptive else f"{self.repeats}"
        return (
            f"{count} x ({seq}) moves to {self.speed_rpm:.0f} rpm, {self.ramp_s * 1000:.0f} ms ramps "
            f"({self.speed_rpm / self.ramp_s:.0f} rpm/s), {self.move_travel_rev:.2f} rev per move, "
            f"{self.excursion_rev:.2f} rev of travel in all (limit {self.travel_limit_rev:g} rev), about "
            f"{self.duration_s:.1f} s; a pilot move at a quarter of that speed first"
            + (
                "; the speed is lowered so that a dead host's run-on stays inside the travel"
                if self.run_on_limited
                else ""
            )
        )


def plan_motion(
    profile: Profile,
    *,
    max_speed: float | None,
    accel_time_ms: float | None,
    travel_rev: float,
    direction: str,
    repeats: int | None,
    samples_per_s: float | None = None,
) -> MotionPlan:
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
        ramp = min(0.5, max(MIN_RAMP_S, SAMPLES_PER_RAMP / rate))
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
    plan = MotionPlan(speed, ramp, dirs, cycles, travel_rev, adaptive, limit)
    if speed < MIN_SPEED_RPM:
        raise UsageError(
            f"travel limit {travel_rev:g} rev is too small for an identification with "
            f"{ramp * 1000:.0f} ms ramps (needs at least {30 / 60 * ramp / 0.9:.2f} rev per move); "
            "raise --travel, shorten --accel-time" + (" or use --direction both" if len(dirs) == 1 else "")
        )
    if plan.excursion_rev > travel_rev:
        raise UsageError(f"the motion needs {plan.excursion_rev:.2f} rev, over the --travel limit {travel_rev:g}")
    return plan


def plan_host_motion(
    drive: Drive,
    timing: Clock | None = None,
    *,
    max_speed: float | None = None,
    accel_time_ms: float | None = None,
    travel_rev: float = 2.0,
    direction: str = "both",
    repeats: int | None = None,
) -> tuple[MotionPlan, RestCheck]:
    """The host method's motion as every caller runs it (CLI, plans, bench): the options checked before anything is
    read, the axis checked at rest, then the plan for the sampling rate that check measured.

    accel_time_ms and repeats None: automatic (ramps from the sampling rate, repeats until precise enough).
    """
    options = {
        "max_speed": max_speed,
        "accel_time_ms": accel_time_ms,
        "travel_rev": travel_rev,
        "direction": direction,
        "repeats": repeats,
    }
    plan_motion(drive.profile, **options)
    rest = check_at_rest(drive, timing)
    plan = fit_run_on(drive, plan_motion(drive.profile, **options, samples_per_s=rest.samples_per_s))
    return with_needs(plan, drive, rest), rest


def with_needs(plan: MotionPlan, drive: Drive, rest: RestCheck) -> MotionPlan:
    """The plan with what the line needs for the fit's limit (tuning.budget), said before the first move, and the
    time the motor alone needs over its travel as its time budget. Automatic plans out and back only: a plan with
    its own ramps or repeats, or one direction, is the user's."""
    p = drive.profile
    if not plan.adaptive or p.motor is None:
        return plan
    limit_e = p.role("torque_limit_fwd")
    limit = float(raw_to_eng(limit_e, drive.read_entries([limit_e])[0].raw)) if limit_e is not None else None
    line = budget.Line(
        samples_per_s=rest.samples_per_s,
        torque_step_pct=p.need_role("torque_feedback", FEATURE).scale,
        torque_noise_pct=rest.torque_noise_pct,
        speed_noise_rpm=rest.speed_noise_rpm,
        speed_step_rpm=p.need_role("speed_feedback", FEATURE).scale,
        rotor_kgm2=p.motor.rotor_inertia_kgcm2 * 1e-4,
        rated_nm=p.motor.rated_torque_nm,
        speed_cap_rpm=plan.speed_limit_rpm,
        torque_limit_pct=limit,
        ramp_s=plan.ramp_s,
        speed_share=plan.speed_rpm / (0.9 * plan.travel_limit_rev / plan.ramp_s * 60.0) if plan.run_on_limited else 1.0,
    )
    found = budget.needs(line, plan.travel_limit_rev, EstimatorSettings().max_rel_uncertainty)
    planned = replace(plan, needs=found, time_limit_s=found.most_s)
    return planned.budgeted(found.lightest.time_s) if found.enough else planned


def identification_bound(drive: Drive, plan: MotionPlan) -> DeadManBound:
    """What a dead host lets the motor run on during this identification, as printed before moving. Most drives:
    the route's bound at the test speed. The segment route (IS620P): each test move is one segment of its own where
    that is no longer than a re-armed one (SegmentMoves.length_rev), ending where the move was to end anyway; the
    pilot's moves are re-armed segments at a quarter of the speed."""
    return _reach(drive, plan)[0]


def _reach(drive: Drive, plan: MotionPlan) -> tuple[DeadManBound, float]:
    """(the printed bound, how far from its start the axis can get if the host dies at the worst moment)."""
    beat = min(0.1, keepalive_interval_s(drive))
    reference = drive.profile.ramp_rpm()
    timeout = deadman.drive_timeout_s(drive) if drive.profile.role("comm_timeout") is not None else None

    def ramp_ms(speed: float) -> float:  # the ramp set so that the move reaches its speed in ramp_s
        return plan.ramp_s * 1000.0 * reference / speed

    def at(speed: float) -> DeadManBound:
        return deadman.bound(drive, speed, beat, ramp_ms(speed), drive.dead_man_waived, timeout)

    test = at(plan.speed_rpm)
    if test.stop_rev is None:
        return test, math.inf
    if test.route != "segment":
        return test, plan.excursion_rev + test.stop_rev
    pilot_speed = plan.speed_rpm * PILOT_SHARE
    # The pilot runs re-armed segments from rest, each SEGMENT_BEATS beats at its speed and its braking from where
    # it started; its stop command comes before a second one is due (so no braked segment runs before a queued one).
    pilot_rev = deadman.segment_rev(pilot_speed, beat, ramp_ms(pilot_speed), reference)
    pilot_s = deadman.SEGMENT_BEATS * beat + plan.ramp_s
    test_rev = deadman.segment_rev(plan.speed_rpm, beat, ramp_ms(plan.speed_rpm), reference)
    assert test.stop_s is not None
    own = plan.move_travel_rev <= test_rev  # SegmentMoves.length_rev: a single segment that ends where its move does
    moves = (plan.move_travel_rev, 2.0 * plan.ramp_s) if own else (test.stop_rev, test.stop_s)
    reach = max(plan.excursion_rev + (0.0 if own else test.stop_rev), pilot_rev)
    return replace(test, stop_rev=max(moves[0], pilot_rev), stop_s=max(moves[1], pilot_s)), reach


def fit_run_on(drive: Drive, plan: MotionPlan) -> MotionPlan:
    """The plan's travel and what a dead host lets the motor run on beyond it fit inside the travel limit: else
    the speed is lowered until they do, or (not even 30 rpm) refused naming a longer travel or a shorter watchdog.
    Nothing to fit where nothing bounds the run-on (--no-dead-man: the NO DEAD-MAN line says so)."""
    bound, reach = _reach(drive, plan)
    if not bound.bounded or reach <= plan.travel_limit_rev:
        return plan
    speed = deadman.largest_fitting_speed(
        plan.speed_rpm,
        lambda v: _reach(drive, replace(plan, speed_rpm=v))[1] <= plan.travel_limit_rev,
        MIN_SPEED_RPM,
    )
    if speed is None:
        raise UsageError(
            f"travel limit {plan.travel_limit_rev:g} rev leaves no room for an identification and what a dead host "
            f"lets the motor run on ({bound.stop_rev:.2f} rev at {plan.speed_rpm:.0f} rpm, {bound.route}): raise "
            f"--travel{deadman.timeout_remedy(drive, bound)}"
        )
    return replace(plan, speed_rpm=speed, run_on_limited=True)


# A suggested travel aims this far past the shortfall, and is at least MIN_REMEDY_GAIN times the old one: the
# uncertainty falls with the acceleration but less than in proportion (a faster move loses more samples to the
# loop's kinks), and a few moves' jackknife misjudges it by a third (bench/inertia_accuracy.py --remedies counts how
# many refusals the suggestion cures).
REMEDY_MARGIN = 1.6
MIN_REMEDY_GAIN = 2.0


@dataclass(frozen=True)
class Remedy:
    """A longer travel for a host identification refused for too little excitation where the travel bounded its
    moves: at the same ramps the speed, the acceleration and its torque grow in proportion to the travel, where more
    repeats help far less on a slow line."""

    travel_rev: float  # the travel limit the motion had
    suggested_rev: float  # the one to ask for
    gain: float  # how many times harder the moves would accelerate with it
    enough: bool  # whether that covers the shortfall, with REMEDY_MARGIN
    bound: str  # what bounds the moves beyond it: "torque" or "speed" (rated or --max-speed)
    time_s: float | None = None  # the time the line's budget (tuning.budget) gives the motion at that travel

    def words(self) -> str:
        said = (
            f"its moves were bound by the {self.travel_rev:g} rev travel: where the axis has room, --travel "
            f"{self.suggested_rev:g}"
            + (f" (about {self.time_s:.0f} s)" if self.time_s is not None else "")
            + f" lets them accelerate {self.gain:.1f}x harder"
        )
        if self.enough:
            return said + ": the uncertainty usually falls with it"
        limit = "the torque share of the limit" if self.bound == "torque" else "the speed limit (rated or --max-speed)"
        return said + f", as far as {limit} allows: that may not be enough"


def remedy(travel_rev: float, shortfall: float, speed_rpm: float, cap_rpm: float, bound: str) -> Remedy | None:
    """The travel that would let a refused host identification succeed, or None where more travel would not help
    (the data fell short by nothing a stronger acceleration cures, or the moves already reach `cap_rpm`).

    speed_rpm: the test speed the travel allowed; cap_rpm: the highest that `bound` ("torque": the torque share of
    the limit, "speed": the motor's rated speed or --max-speed) allows at the same ramps."""
    if not (math.isfinite(shortfall) and shortfall > 1.0) or speed_rpm <= 0:
        return None
    room = cap_rpm / speed_rpm
    if room < MIN_REMEDY_GAIN:
        return None
    wanted = max(MIN_REMEDY_GAIN, REMEDY_MARGIN * shortfall)
    suggested = (
        math.ceil(travel_rev * wanted * 2.0) / 2.0 if room >= wanted else math.floor(travel_rev * room * 2.0) / 2.0
    )
    return Remedy(travel_rev, suggested, suggested / travel_rev, room >= wanted, bound)
