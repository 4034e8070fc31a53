"""What a host identification needs of the line before it moves: the travel and the time in which the inertia fit
can reach its uncertainty limit, from what the rest check measured (the sampling rate, the speed and torque
readings' noise), the torque reading's step, the motor and the torque the drive allows.

J is seen through the acceleration torque J*a against the torque reading's error. The planned moves accelerate and
brake along ramps of a fixed time (planning: a number of samples each); a longer travel lets them reach a higher
speed in the same ramp, so the acceleration and its torque grow in proportion to the travel, up to the motor's speed
and the torque the drive may spend (a share of its limit, and an r.m.s. over the motion that its I^2t overload
protection carries indefinitely). Every sample inside a ramp, less the one at each end (a torque step, which the fit
leaves out), carries J*a / sigma_T of information, so

    sigma(J)/J ~= EFFICIENCY * sigma_T / (tau_a * sqrt(N))

sigma_T: the torque reading's noise and its step (q/sqrt 12); tau_a: the acceleration torque, % of rated; N: the
samples inside ramps within the time. A reading whose steps stay put through an acceleration adds a floor no N
averages away (step_floor, as the fit adds it: fit.quantization). EFFICIENCY is how far `tune inertia`'s fit
(friction, gravity and viscous terms fitted beside J, windows clear of the steps, the jackknife's honesty) stays
from that ideal, measured on the bench's machines (bench/inertia_accuracy.py). The lightest load (the motor alone)
needs the most: the travel and time named before moving are its, and a heavier load, once the pilot has shown it,
needs less.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

from servotool.tuning.fit import quantization

# The fit's uncertainty against the ideal one, measured (bench/inertia_accuracy.py): 1.2-2.7 where the acceleration
# torque is weak (the loads that need travel), more where it is strong (friction and gravity then weigh as much as J,
# but the uncertainty is far below the limit anyway).
EFFICIENCY = 3.5
# ... and the best the bench measured: a run that did better than the model is scaled down to this, no further (SDC
# 9600, the motor alone with 0.5-1 % noise: 4-7 % at 2 rev, so no travel was named, where 13-15 rev reach 1.6-2 %)
BEST_EFFICIENCY = 1.2
TARGET_SHARE = 0.7  # the prediction aims this far below the limit: a few moves' jackknife misjudges by a third
MOTION_SHARE = 0.85  # of the rest check's sampling rate, what the motion keeps (position reads, commands)
RMS_TORQUE_PCT = 80.0  # an r.m.s. torque, % of rated, that an overload protection carries indefinitely (not a cap)
TORQUE_SHARE = 0.6  # of the drive's torque limit, what an acceleration may take
DEFAULT_LIMIT_PCT = 300.0  # a drive whose limit servotool cannot read: the usual servo motor's peak
MIN_EXCITATION = 10.0 * math.sqrt(2.0) * 1.3  # the speed change a window needs against the speed noise, with margin
ZERO_BAND_SIGMAS = 3.0  # the fit's zero-speed band, in speed noises (fit.signals), which no window enters
MAX_TRAVEL_REV = 100.0  # beyond this no travel is named: the line cannot do it
MIN_TIME_S = 8.8  # an identification's time budget where the line needs no more
MAX_TIME_S = 30.0  # ... nor a time longer than this
LATE_TIME_FACTOR = 2.0  # where the travel serves every load, a late host's run takes at most this many of its time
TIME_TIERS_S = (10.0, MAX_TIME_S)  # a usual identification's time, and the longest
TRAVEL_FOR_TIME = 1.5  # a usual time is worth up to this many times the least travel
MOVE_REQUESTS = 3  # requests a move spends outside its ramps: the start, the stop, the alarm check
TIME_OVERHEAD_S = 1.0  # the pilot's fit and the hold's set-up
# A travel named is planned for a speed noise this much larger than the rest check measured: the run that follows it
# measures it again (DSX7E 115200, 1 % noise: named 6 rev before moving, the run at 6 rev measured 7 % more speed
# noise and stopped after its pilot naming 6.5).
NAMING_MARGIN = 1.2
DITHER_MIN = 0.4  # an identification on a coarse torque reading spreads its accelerations over [this, 1] (planning)
STILL_NOISE = 0.1  # a torque noise under this share of the reading's step hardly moves it (steps_hide)
LOAD_RATIOS = (0.0, 0.5, 1.0, 2.0, 3.0, 5.0, 7.0, 10.0, 15.0, 20.0, 30.0, 50.0, 100.0, 200.0)


@dataclass(frozen=True)
class Line:
    """What the rest check measured and the drive states, that the budget depends on."""

    samples_per_s: float
    torque_step_pct: float  # the torque reading's resolution, % of rated
    torque_noise_pct: float  # 1 sigma, % of rated
    speed_noise_rpm: float
    rotor_kgm2: float
    rated_nm: float
    speed_cap_rpm: float  # rated, or --max-speed below it
    torque_limit_pct: float | None  # the drive's torque limit, % of rated (None: unknown)
    ramp_s: float  # the planned ramps' time
    efficiency: float = 1.0  # this machine's fit against the model's (>= 1: as a pilot or a run showed it)
    # Of the speed the travel allows, what a dead host's run-on leaves (planning.fit_run_on): the run-on and the move
    # both grow in proportion to the speed at the planned ramps, so one share holds at every travel.
    speed_share: float = 1.0
    # Of the model's speed change per window, what the fit's windows see (< 1: as a run showed it).
    excitation_share: float = 1.0
    speed_step_rpm: float = 0.0  # the speed reading's resolution, rpm

    @property
    def sigma_torque_pct(self) -> float:
        return math.hypot(self.torque_noise_pct, self.torque_step_pct / math.sqrt(12.0))

    @property
    def sigma_speed_rpm(self) -> float:
        """The speed noise the fit counts (fit.signals.speed_noise_rpm): the measured, at least the step's rounding."""
        return max(self.speed_noise_rpm, self.speed_step_rpm / math.sqrt(12.0))

    @property
    def torque_cap_pct(self) -> float:
        return torque_cap_pct(self.torque_limit_pct)


def torque_cap_pct(limit_pct: float | None) -> float:
    """The acceleration torque a move may take (% of rated): a share of the drive's limit (the rest: friction and
    gravity). An r.m.s. cap of RMS_TORQUE_PCT (what the overload protection carries indefinitely) was tried: it cut a
    bare motor's moves at 57600 baud and 12 rev of travel below the 2 % limit (test_dither); the drive's own I^2t
    protection stops a motion that overloads it, with an alarm the identification names."""
    return TORQUE_SHARE * (limit_pct or DEFAULT_LIMIT_PCT)


def torque_speed_cap(speed_rpm: float, peak_pct: float, swing_pct: float, limit_pct: float | None) -> float:
    """The test speed (rpm) at which moves like one at speed_rpm (the same ramps), whose |torque| peaked at peak_pct
    of which swing_pct was the acceleration's (half the step between accelerating and braking torque), take the
    acceleration torque torque_cap_pct allows, the rest (friction and gravity, which do not grow with the speed)
    within the drive's limit: the cap `predicted` plans by. Never below the speed at which the whole peak, scaled,
    would reach torque_cap_pct; inf where the move took no torque. Scaling the whole peak capped a bare motor with
    30 % friction and 40 % gravity at 1900 rpm where the budget planned 3000: a travel named past that ran weaker
    than planned and was refused for the torque reading's floor (SDC 7600, 26 rev named: 2.3 %)."""
    if peak_pct <= 0:
        return math.inf
    cap = torque_cap_pct(limit_pct)
    whole = speed_rpm * cap / peak_pct
    swing = min(swing_pct, peak_pct)
    if swing <= 0:
        return math.inf
    room = min(cap, (limit_pct or DEFAULT_LIMIT_PCT) - (peak_pct - swing))
    return max(whole, speed_rpm * room / swing)


@dataclass(frozen=True)
class Need:
    """The travel and time a load needs on this line; `reachable` False: none within MAX_TRAVEL_REV and MAX_TIME_S
    (travel and time then say what came closest)."""

    load_ratio: float
    travel_rev: float
    time_s: float
    sigma_rel: float  # the uncertainty predicted with them
    speed_rpm: float
    reachable: bool
    bound: str  # what bounds the moves at that travel: "travel", "speed" or "torque"

    def nameable(self, target: float) -> bool:
        """Whether its travel may be named: reachable, or (what came closest) predicted within `target` itself, as
        one that may not be enough (more_travel's closest)."""
        return self.reachable or self.sigma_rel <= target

    def words(self, target: float) -> str:
        what = "the motor alone" if self.load_ratio <= 0 else f"a load ratio of {self.load_ratio:.2g}"
        if not self.reachable and self.nameable(target):
            return (
                f"{what} needs {self.travel_rev:g} rev of travel and about {self.time_s:.0f} s at best "
                f"({100 * self.sigma_rel:.1f} % predicted, the moves bound by the {self.bound}), within "
                f"{100 * target:g} % but short of the margin planned: that may not be enough"
            )
        if not self.reachable:
            return (
                f"this line cannot reach {100 * target:g} % for {what} within {MAX_TRAVEL_REV:g} rev and "
                f"{MAX_TIME_S:g} s (at best {100 * self.sigma_rel:.1f} %, the moves bound by the {self.bound})"
            )
        return f"{what} needs {self.travel_rev:g} rev of travel and about {self.time_s:.0f} s for {100 * target:g} %"


def move_s(line: Line) -> float:
    """A move's time: its two ramps and the requests around them."""
    return 2.0 * line.ramp_s + MOVE_REQUESTS / (line.samples_per_s * MOTION_SHARE)


def moves_in(line: Line, time_s: float) -> int:
    """Moves (out or back) that fit in time_s after the set-up and the pilot (one cycle)."""
    return max(0, int((time_s - TIME_OVERHEAD_S) / move_s(line)) - 2)


def time_for(line: Line, moves: int) -> float:
    """The time budget for `moves` moves, the pilot and the set-up included: no less than a usual identification's
    (MIN_TIME_S), which the adaptive repeats end early once the estimate is precise."""
    return max(MIN_TIME_S, TIME_OVERHEAD_S + (moves + 2) * move_s(line))


def predicted(
    line: Line,
    load_ratio: float,
    travel_rev: float,
    moves: int,
    rpm_per_rev: float | None = None,
    scale: float = 1.0,
    floor: bool = True,
) -> tuple[float, float, str]:
    """(sigma(J)/J, test speed rpm, what bounds it) of `moves` moves (out and back) within travel_rev; rpm_per_rev:
    the test speed a revolution of travel gives, as a run showed it (None: the planned ramps' own, with room for
    the move's swing, less what a dead host's run-on takes: Line.speed_share). scale: the statistical part's, as a
    run showed it (the torque reading's step floor is the reading's, not the machine's); floor False: that part
    alone."""
    per_rev = line.speed_share * 0.9 / line.ramp_s * 60.0 if rpm_per_rev is None else rpm_per_rev
    speed, bound = per_rev * travel_rev, "travel"
    if speed >= line.speed_cap_rpm:
        speed, bound = line.speed_cap_rpm, "speed"
    tau = accel_torque_pct(line, load_ratio, speed)
    if tau > line.torque_cap_pct:
        speed *= line.torque_cap_pct / tau
        tau, bound = line.torque_cap_pct, "torque"
    inside = _ramp_samples(line)[1]
    n = 2.0 * moves * inside
    if n <= 0 or tau <= 0:
        return math.inf, speed, bound
    # Each window's speed change against the speed noise (fit.windows): too little and the fit refuses outright.
    if excitation(line, speed) < MIN_EXCITATION:
        return math.inf, speed, bound
    statistical = scale * line.efficiency * EFFICIENCY * line.sigma_torque_pct / (tau * math.sqrt(n))
    return math.hypot(statistical, step_floor(line, tau, moves) if floor else 0.0), speed, bound


def accel_torque_pct(line: Line, load_ratio: float, speed_rpm: float) -> float:
    """The acceleration torque (% of rated) of the planned ramps up to speed_rpm for this load."""
    j = line.rotor_kgm2 * (1.0 + max(load_ratio, 0.0))
    return j * speed_rpm * math.pi / 30.0 / line.ramp_s / line.rated_nm * 100.0


def steps_hide(line: Line, tau_pct: float) -> bool:
    """Whether the torque reading's steps hide an acceleration torque of tau_pct: within one step, on a reading whose
    noise hardly moves it (under STILL_NOISE of a step). A fit of such moves is as uncertain as its steps' luck makes
    it, not as the model's noise has it, and sets no scale for stronger moves (more_travel): SDC's bare motor with
    30 % friction and 40 % gravity at 19.6 samples/s in real time came out 3.1 % at 2 rev, 8.5 rev were named from
    it and refused at 2.2 %. A noisier reading (0.2-0.5 % on a 1 % step) scales as it showed."""
    q = line.torque_step_pct
    return q > 0 and tau_pct < q and line.torque_noise_pct < STILL_NOISE * q


def step_floor(line: Line, tau_pct: float, moves: int) -> float:
    """The floor a torque read in coarse steps sets on sigma(J)/J (fit.quantization, which the fit adds last), for
    moves whose acceleration torque is tau_pct, dithered over [DITHER_MIN, 1] of it (tuning.identify): no number of
    samples averages away a reading that stays on one step through an acceleration. A reading whose noise moves it
    between steps (half a step or more) leaves none. Without it the budget named SDC 9600's motor alone with 30 %
    friction and 40 % gravity 7 rev, then 23, then 26: each run refused for the floor ("the torque reads in 1 %
    steps against an acceleration torque of 1.8 %")."""
    q = line.torque_step_pct
    if q <= 0 or tau_pct <= 0:
        return 0.0
    stuck = max(0.0, 1.0 - 2.0 * line.torque_noise_pct / q)
    share = quantization.repeated_share((1.0 - DITHER_MIN) * tau_pct / q)
    return quantization.relative_floor(q, stuck, tau_pct, share, moves)


def _ramp_samples(line: Line) -> tuple[float, float]:
    """(samples in a ramp as the motion samples, those clear of its two ends: a torque step each)."""
    in_ramp = line.samples_per_s * MOTION_SHARE * line.ramp_s
    return in_ramp, max(0.0, in_ramp - 2.0)


def excitation(line: Line, speed_rpm: float) -> float:
    """A ramp's speed change clear of its ends and of the fit's zero-speed band (fit.signals: ZERO_BAND_SIGMAS of
    the speed noise), in speed noises, as the fit's windows see it (Line.excitation_share); inf where the speed reads
    exactly (no noise, no step)."""
    noise = line.sigma_speed_rpm
    if noise <= 0:
        return math.inf
    in_ramp, inside = _ramp_samples(line)
    change = speed_rpm * inside / in_ramp - ZERO_BAND_SIGMAS * noise
    return line.excitation_share * change / noise


def within(line: Line, load_ratio: float, travel_rev: float, target: float, time_cap_s: float = MAX_TIME_S) -> Need:
    """The least time in which moves over travel_rev are predicted to reach TARGET_SHARE of `target` for this load
    (`reachable` False: not within time_cap_s)."""
    aim = TARGET_SHARE * target
    most = moves_in(line, time_cap_s)
    sigma, speed, bound = predicted(line, load_ratio, travel_rev, most)
    if sigma > aim:
        return Need(load_ratio, travel_rev, time_cap_s, sigma, speed, False, bound)
    moves = _fewest_moves(line, load_ratio, travel_rev, aim, most)
    return Need(load_ratio, travel_rev, time_for(line, moves), sigma, speed, True, bound)


def naming_line(line: Line) -> Line:
    """The line a travel is named for: its speed noise NAMING_MARGIN larger than measured (the excitation's limit is
    a hard one; the uncertainty's aim has its own margin, TARGET_SHARE)."""
    return replace(line, speed_noise_rpm=NAMING_MARGIN * line.speed_noise_rpm)


def need(line: Line, load_ratio: float, target: float) -> Need:
    """The least travel (in steps of half a revolution) with which the fit is predicted to reach TARGET_SHARE of
    `target` for this load within MAX_TIME_S, and the least time with it; or, where at most TRAVEL_FOR_TIME times that
    travel does it within a usual time (TIME_TIERS_S[0]), that travel and time: travel is what an axis lacks, time
    only costs time. Not reachable: what came closest. The travel named is planned for a speed reading NAMING_MARGIN
    noisier than this rest check measured: the run that follows it measures it again, and must find it enough."""
    line = naming_line(line)
    found = [_least_travel(line, load_ratio, target, time_s) for time_s in TIME_TIERS_S]
    quick, least = found[0], found[-1]
    if quick.reachable and least.reachable and quick.travel_rev <= TRAVEL_FOR_TIME * least.travel_rev:
        return quick
    return least if least.reachable or not quick.reachable else quick


def _least_travel(line: Line, load_ratio: float, target: float, time_s: float) -> Need:
    best: Need | None = None
    travel = 0.5
    while travel <= MAX_TRAVEL_REV + 1e-9:
        found = within(line, load_ratio, travel, target, time_s)
        if found.reachable:
            return found
        if best is None or found.sigma_rel < best.sigma_rel:
            best = found
        if found.bound != "travel":  # the speed or the torque bounds the moves: more travel changes nothing
            break
        travel += 0.5
    assert best is not None
    return best


def _fewest_moves(
    line: Line,
    load_ratio: float,
    travel: float,
    aim: float,
    most: int,
    rpm_per_rev: float | None = None,
    scale: float = 1.0,
) -> int:
    lo, hi = 2, max(2, most)
    while lo < hi:
        mid = (lo + hi) // 2
        if predicted(line, load_ratio, travel, mid, rpm_per_rev, scale)[0] <= aim:
            hi = mid
        else:
            lo = mid + 1
    return lo


@dataclass(frozen=True)
class Needs:
    """What the line needs for the target, said before the first move: the lightest load's travel and time, and the
    lightest load that the travel allowed serves."""

    line: Line
    target: float
    allowed_rev: float
    lightest: Need  # the motor alone
    from_ratio: float | None  # the lightest load (of LOAD_RATIOS) the allowed travel serves; None: none of them
    # where no travel serves the motor alone: the lightest load (of LOAD_RATIOS) some travel serves, and that travel
    lightest_served: Need | None = None

    @property
    def named(self) -> Need | None:
        """The travel to name where more is needed: the motor alone's, or the lightest load's some travel serves."""
        return self.lightest if self.lightest.reachable else self.lightest_served

    @property
    def enough(self) -> bool:
        """Whether the allowed travel serves every load."""
        return self.lightest.reachable and self.lightest.travel_rev <= self.allowed_rev

    @property
    def most_s(self) -> float:
        """The longest a run over the travel allowed takes, said before moving and held to (MotionPlan.time_limit_s):
        where that travel serves every load, the time the line needs, LATE_TIME_FACTOR times it for a host that turns
        out late (time buys back the samples it lost: tuning.identify); else MAX_TIME_S, since there time is what buys
        the precision a short travel lacks, and the pilot or the fit may take all of it."""
        if not self.enough:
            return MAX_TIME_S
        return min(MAX_TIME_S, LATE_TIME_FACTOR * self.lightest.time_s)  # time_for: at least MIN_TIME_S

    def words(self) -> str:
        line = self.line
        said = (
            f"for {100 * self.target:g} % at {line.samples_per_s:.0f} samples/s (torque in {line.torque_step_pct:g} % "
            f"steps, noise {line.torque_noise_pct:.2g} %): {self.lightest.words(self.target)}"
        )
        limit = f"; the run takes at most {self.most_s:.0f} s"
        if self.enough:
            return said + limit + " (twice the time named, where the host turns out late)"
        if self.lightest_served is not None:
            said += f"; {self.lightest_served.words(self.target)}"
        if self.from_ratio is None:
            said += f"; {self.allowed_rev:g} rev serve none of the loads up to a ratio of {LOAD_RATIOS[-1]:g}"
        else:
            said += f"; {self.allowed_rev:g} rev serve load ratios from {self.from_ratio:g}"
        return said + limit + " (time buys the precision the travel lacks)"


def needs(line: Line, allowed_rev: float, target: float) -> Needs:
    """What this line needs for `target`: the motor alone over the travel allowed (the moves always use all of it),
    else the travel it needs; and then the lightest load the travel allowed serves."""
    lightest = within(line, 0.0, allowed_rev, target)
    if lightest.reachable:
        return Needs(line, target, allowed_rev, lightest, 0.0)
    served = next((r for r in LOAD_RATIOS if within(line, r, allowed_rev, target).reachable), None)
    lightest = need(line, 0.0, target)
    if lightest.reachable:
        return Needs(line, target, allowed_rev, lightest, served)
    heavier = (need(line, r, target) for r in LOAD_RATIOS[1:])
    return Needs(line, target, allowed_rev, lightest, served, next((n for n in heavier if n.reachable), None))


def given_s(line: Line, load_ratio: float, travel_rev: float, target: float) -> float:
    """The time a run over travel_rev is given for this load (tuning.identify's cycles): where the travel serves the
    motor alone, the budget the load's own need sets (the pilot's, no longer: a run that falls short there ends
    refused, since the time named before moving is what it may take); else up to MAX_TIME_S (the budget is extended
    towards the precision where travel is what the line lacks)."""
    if not within(line, 0.0, travel_rev, target).reachable:
        return MAX_TIME_S
    return within(line, load_ratio, travel_rev, target).time_s


def more_travel(
    line: Line,
    load_ratio: float,
    travel_rev: float,
    moves: int,
    sigma_rel: float,
    target: float,
    excitation_seen: float = math.nan,
    speed_rpm: float | None = None,
    closest: bool = False,
) -> Need | None:
    """The least travel beyond travel_rev with which a run that came out sigma_rel uncertain (the torque reading's
    step floor taken out) after `moves` moves
    would reach TARGET_SHARE of `target` within the time such a run is given (given_s), the model scaled to what
    this run showed (its uncertainty, and excitation_seen: the fit's speed change per window against sqrt(2) speed
    noises, where it was refused for too little of it); None where no travel up to MAX_TRAVEL_REV does (the speed
    or the torque bounds the moves, or the line is too slow). A longer travel's time is the one its own run will
    plan, not MAX_TIME_S: a remedy counted on 30 s that its run, served at 8.8 s, never took (lost motion at 4 rev:
    --travel 4.5 'about 23 s', refused again at 8 s). speed_rpm: the run's test speed, which a longer travel raises
    in proportion (at the same ramps) up to the speed and torque caps (None: the planned one). closest: where no
    travel reaches TARGET_SHARE of `target`, the least at which the speed or the torque bounds the moves, where its
    prediction is within `target` itself (`reachable` False: one that may not be enough; the bench's runs named
    "no travel" there were accepted when that travel was given: SDC 19 samples/s, the motor alone with 30 %
    friction and 40 % gravity, 1.47 % predicted at 25 rev, 1.7-2.0 % at 20-30 rev)."""
    if not (math.isfinite(sigma_rel) or math.isfinite(excitation_seen)):
        return None
    per_rev = speed_rpm / travel_rev if speed_rpm is not None and speed_rpm > 0 else None
    speed_now = predicted(line, load_ratio, travel_rev, max(moves, 2), per_rev)[1]
    model = excitation(line, speed_now)
    if math.isfinite(excitation_seen) and excitation_seen > 0 and 0 < model < math.inf:
        seen = line.excitation_share * math.sqrt(2.0) * excitation_seen / model  # the fit's unit: sqrt(2) noises
        line = replace(line, excitation_share=min(line.excitation_share, seen))
    now = predicted(line, load_ratio, travel_rev, max(moves, 2), per_rev, floor=False)[0]
    # this machine's fit against the model's, where both stand (a refusal for too little excitation has no fit); the
    # torque reading's floor (sigma_rel has it taken out) stays the model's at every travel
    scale = (
        max(BEST_EFFICIENCY / EFFICIENCY, sigma_rel / now) if math.isfinite(sigma_rel) and 0 < now < math.inf else 1.0
    )
    if steps_hide(line, accel_torque_pct(line, load_ratio, speed_now)):
        scale = max(scale, 1.0)
    aim = (1.0 if closest else TARGET_SHARE) * target
    line = naming_line(line)
    for travel, time_s, most, sigma, speed, bound in _longer(line, load_ratio, travel_rev, target, per_rev, scale):
        if closest and bound == "travel":
            continue
        if sigma <= aim and not closest:
            moves = _fewest_moves(line, load_ratio, travel, aim, most, per_rev, scale)
            return Need(load_ratio, travel, time_for(line, moves), sigma, speed, True, bound)
        if bound != "travel":
            return Need(load_ratio, travel, time_s, sigma, speed, False, bound) if sigma <= aim else None
    return None


def strongest_travel(
    line: Line, load_ratio: float, travel_rev: float, target: float, speed_rpm: float | None = None
) -> Need | None:
    """The least travel beyond travel_rev (in steps of half a revolution, up to MAX_TRAVEL_REV) at which the moves
    reach the speed or the torque the drive allows, so that no longer one accelerates them harder, with the time its
    run is given; None where they reach it already. What a refusal names where the fit's uncertainty was widened by
    a check the line's model does not predict (tuning.identify): the strongest motion, which no model says is
    enough. speed_rpm: as more_travel has it."""
    per_rev = speed_rpm / travel_rev if speed_rpm is not None and speed_rpm > 0 else None
    if predicted(line, load_ratio, travel_rev, 2, per_rev)[2] != "travel":
        return None
    last = None
    for travel, time_s, _most, sigma, speed, bound in _longer(line, load_ratio, travel_rev, target, per_rev):
        last = Need(load_ratio, travel, time_s, sigma, speed, False, bound)
        if bound != "travel":
            break
    return last


def _longer(
    line: Line, load_ratio: float, travel_rev: float, target: float, per_rev: float | None, scale: float = 1.0
) -> Iterator[tuple[float, float, int, float, float, str]]:
    """Each travel beyond travel_rev, in steps of half a revolution up to MAX_TRAVEL_REV: (travel, the time its run
    is given, the moves that time holds, and predicted's sigma, speed and bound for them)."""
    travel = math.floor(travel_rev * 2.0) / 2.0 + 0.5
    while travel <= MAX_TRAVEL_REV + 1e-9:
        time_s = given_s(line, load_ratio, travel, target)
        most = moves_in(line, time_s)
        yield travel, time_s, most, *predicted(line, load_ratio, travel, most, per_rev, scale)
        travel += 0.5
