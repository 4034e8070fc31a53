"""Plan steps for the measured score and the drive's own functions: `tune score`, `tune friction`, `tune notch`,
`tune gain-switching` (the same library calls as the commands: tuning.score.measure and
tuning.function_run.run_function)."""

from __future__ import annotations

from typing import Any

from servotool.commission.motion_steps import waived
from servotool.commission.plan import Step
from servotool.commission.step_type import Outcome, RunContext, StepType, number_in
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.motion.deadman import sentence
from servotool.motion.stop import proven_on_interrupt
from servotool.tuning import function_run as use
from servotool.tuning import gain_switching
from servotool.tuning import score as scoring
from servotool.tuning import step as step_check

SCORE_KEYS = {"repeats", "travel", "speed", "no_dead_man"}
FUNCTION_KEYS = {"repeats", "travel", "keep", "save", "no_dead_man"}
OWN_KEYS = {"notch": {"method"}, "gain-switching": {"factor"}}  # a function's own options


def _options(step: Step, keys: set[str]) -> dict[str, Any]:
    opts = step.arg if step.arg is not None else {}
    if not isinstance(opts, dict) or set(opts) - keys:
        raise UsageError(f"{step.name} options are {', '.join(sorted(keys))}")
    return opts


def _flag(opts: dict[str, Any], key: str, what: str) -> bool | None:
    value = opts.get(key)
    if value is not None and not isinstance(value, bool):
        raise UsageError(f"{what} {key} must be true or false")
    return value


def _motion(step: Step, opts: dict[str, Any]) -> tuple[scoring.ScoreMotion, int]:
    """The test motion and its repeats, as `tune score --travel --speed --repeats` check them."""
    repeats = number_in(opts.get("repeats", scoring.DEFAULT_REPEATS), f"{step.name} repeats", 1, scoring.MAX_REPEATS)
    if repeats != int(repeats):
        raise UsageError(f"{step.name} repeats must be a whole number 1..{scoring.MAX_REPEATS}")
    travel = number_in(opts.get("travel", 2.0), f"{step.name} travel", 0, 10_000)
    speed = number_in(opts.get("speed", step_check.STEP_SPEED_RPM), f"{step.name} speed", 1, 100_000)
    return scoring.motion_for(travel, speed), int(repeats)


def _announce(drive: Drive, motion: scoring.ScoreMotion, ctx: RunContext) -> scoring.ScoreMotion:
    """The motion as planned for this drive, its dead-man bound shown before it moves (never quiet)."""
    planned = scoring.planned(drive, motion)
    ctx.safety(f"unit {drive.unit}: {sentence(step_check.plan_step(drive, motion.travel_rev).bound)}")
    return planned


class TuneScoreStep(StepType):
    """`tune score: {repeats, travel, speed}`: the measured score of `servotool tune score` (nothing written but
    the test motion's JOG settings, put back); the step's JSON carries every figure with its unit."""

    name = "tune score"

    def describe(self, step: Step, profile: Profile) -> str:
        opts = _options(step, SCORE_KEYS)
        _flag(opts, "no_dead_man", step.name)
        motion, repeats = _motion(step, opts)
        return f"tune score: {motion.describe()}, {repeats} times"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        motion, repeats = _motion(step, _options(step, SCORE_KEYS))
        drive.dead_man_waived = waived(step.arg)
        with proven_on_interrupt(drive):  # an interrupt before a motion, or between two, ends with a read-back
            motion = _announce(drive, motion, ctx)
            measured = scoring.measure(drive, motion, repeats, ctx.clock)
        data = scoring.score_json(measured, drive.profile.id)
        iae = measured.score.figures["iae"]
        detail = f"scored {repeats} run(s) of {motion.describe()}"
        if iae.value is not None:
            detail += f": integrated abs. error {iae.value:.4f} ± {iae.spread:.4f} rev"
        return Outcome(detail, {"score": data})


class TuneFunctionStep(StepType):
    """`tune friction|notch|gain-switching: {repeats, travel, keep, save}` (notch: method; gain-switching: factor):
    what the command of the same name does (score before, set up, score after, keep or put back, read back); kept
    values count as the plan's writes, so a later `save:` stores them."""

    def __init__(self, function: str) -> None:
        self.function = function
        self.name = f"tune {function}"  # type: ignore[misc]

    def _request(self, step: Step, profile: Profile) -> tuple[scoring.ScoreMotion, int, dict[str, Any], str]:
        opts = _options(step, FUNCTION_KEYS | OWN_KEYS.get(self.function, set()))
        for key in ("keep", "save", "no_dead_man"):
            _flag(opts, key, step.name)
        motion, repeats = _motion(step, opts)
        method = use.check_function(profile, self.function, opts.get("method"))
        if self.function == "friction":
            if profile.role("friction_comp_fwd") is None:
                raise UsageError(f"{step.name}: {profile.model} maps no friction compensation (role friction_comp_fwd)")
        elif self.function == "notch" and profile.role("notch1_freq") is None:
            raise UsageError(f"{step.name}: {profile.model} maps no torque-command notch (roles notchN_freq/..)")
        elif self.function == "gain-switching":
            gain_switching.switching_entries(profile)
            if "factor" in opts:
                gain_switching.check_factor(number_in(opts["factor"], f"{step.name} factor", 1, 4))
        return motion, repeats, opts, method

    def describe(self, step: Step, profile: Profile) -> str:
        motion, repeats, opts, method = self._request(step, profile)
        how = {
            "friction": "compensation from constant-speed torques",
            "notch": f"notch by the {method}",
            "gain-switching": f"gain 2 = {opts.get('factor', gain_switching.DEFAULT_FACTOR):g} x gain 1 while moving",
        }
        keep = "kept even if not better" if opts.get("keep") else "kept only where the score improves"
        return f"{step.name} ({how[self.function]}): {motion.describe()}, {repeats} times before and after, {keep}"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        motion, repeats, opts, _method = self._request(step, drive.profile)
        drive.dead_man_waived = waived(step.arg)
        with proven_on_interrupt(drive):  # an interrupt before a motion, or between two, ends with a read-back
            motion = _announce(drive, motion, ctx)
            trial = use.run_function(
                drive,
                self.function,
                motion,
                repeats,
                method=opts.get("method"),
                keep=bool(opts.get("keep", False)),
                save=opts.get("save"),
                factor=opts.get("factor"),
                clock=ctx.clock,
            )
        if trial.kept:
            for c in trial.changes:
                ctx.wrote(drive, c.entry, c.new)
        held = ", ".join(f"{code} = {value:g}" for code, value in trial.held.items())
        detail = f"{'KEPT' if trial.kept else 'NOT KEPT'}: {trial.reason}" + (f"; holds {held}" if held else "")
        return Outcome(detail, {"result": use.trial_json(trial, drive.profile.id)})
