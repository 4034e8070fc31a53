"""Plan step types by name, the steps that need no drive parameters (wait, alarm clear, prompt), and validating a
whole plan before anything is written."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.commission.function_steps import TuneFunctionStep, TuneScoreStep
from servotool.commission.motion_steps import JogStep, TuneInertiaStep
from servotool.commission.param_steps import BackupStep, ExpectStep, RestoreStep, SaveStep, SetStep
from servotool.commission.plan import Plan, Step
from servotool.commission.plan_files import PlanFile, plan_files
from servotool.commission.step_type import Outcome, RunContext, StepType, no_argument
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.ops import alarms


class WaitStep(StepType):
    """`wait: SECONDS`."""

    name = "wait"

    def describe(self, step: Step, profile: Profile) -> str:
        arg = step.arg
        if not isinstance(arg, int | float) or isinstance(arg, bool) or not 0 <= arg <= 3600:
            raise UsageError("wait takes seconds 0..3600")
        return f"wait {arg:g} s"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        ctx.clock.sleep(float(step.arg))
        return Outcome(f"waited {step.arg:g} s")


class AlarmClearStep(StepType):
    """`alarm clear:`: reset the drive's alarm."""

    name = "alarm clear"

    def describe(self, step: Step, profile: Profile) -> str:
        no_argument(step)
        profile.need_role("alarm_reset", "alarm clear")
        return "clear the alarm"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        before = alarms.current(drive)
        alarms.clear(drive)
        return Outcome(f"cleared {before.display} {before.name}" if before.active else "no alarm was active")


class PromptStep(StepType):
    """`prompt: QUESTION`: the operator confirms (skipped with --yes); a no fails the step."""

    name = "prompt"

    def describe(self, step: Step, profile: Profile) -> str:
        if not isinstance(step.arg, str) or not step.arg:
            raise UsageError("prompt takes the question to ask")
        return f"ask: {step.arg}"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        if ctx.yes:
            return Outcome(f"skipped (--yes): {step.arg}")
        if not ctx.ask(drive.unit, str(step.arg)):
            raise UsageError(f"operator declined: {step.arg}")
        return Outcome(f"confirmed: {step.arg}")


STEP_TYPES: dict[str, StepType] = {
    t.name: t
    for t in (
        SetStep(),
        ExpectStep(),
        BackupStep(),
        RestoreStep(),
        JogStep(),
        TuneInertiaStep(),
        TuneScoreStep(),
        TuneFunctionStep("friction"),
        TuneFunctionStep("notch"),
        TuneFunctionStep("gain-switching"),
        WaitStep(),
        AlarmClearStep(),
        SaveStep(),
        PromptStep(),
    )
}


def step_type(step: Step) -> StepType:
    kind = STEP_TYPES.get(step.name)
    if kind is None:
        raise UsageError(f"unknown step {step.name}")
    return kind


@dataclass(frozen=True)
class Checked:
    """A plan checked as a whole before anything runs: what each step would do, and every file it would use."""

    lines: list[str]  # 'PLAN:LINE: what the step does', one a step
    files: list[PlanFile]


def validate(plan: Plan, profile: Profile, units: list[int] | None = None, *, force: bool = False) -> Checked:
    """Check every step against the profile, and the files the steps use on these axes (the plan's, by default),
    before anything runs. Every problem of the plan is reported at once (one line, '; ' between them), not one per
    run: a real run and its dry run stop at the same ones, before anything moves."""
    lines, problems, uses = [], list(plan.problems), []
    for step in plan.steps:
        try:
            if step.units and plan.units and not set(step.units) <= set(plan.units):
                raise UsageError(f"unit {step.units} is not among the plan's units {plan.units}")
            kind = step_type(step)
            kind.validate(step, profile)
            lines.append(kind.describe(step, profile))
            uses.append((step, kind.files(step, profile)))
        except UsageError as exc:
            msg = str(exc)
            problems.append(msg if msg.startswith(("step ", str(plan.path))) else f"{step.where()}: {msg}")
    files, file_problems = plan_files(plan, units or plan.units or [profile.default_unit], uses, force=force)
    problems += file_problems
    if len(problems) == 1:
        raise UsageError(problems[0])
    if problems:
        raise UsageError(f"{plan.path}: {len(problems)} problems: " + "; ".join(problems))
    return Checked([f"{plan.path}:{s.line}: {d}" for s, d in zip(plan.steps, lines, strict=True)], files)
