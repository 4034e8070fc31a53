"""What every plan step type provides (validate, describe, run), and what a running step may use."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from servotool.clock import Clock, RealClock
from servotool.commission.plan import Plan, Step
from servotool.commission.plan_files import FileUse, resolve
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.profile import Entry, Profile


@dataclass
class RunContext:
    """The plan run around one step: operator answers, what the plan wrote so far (for 'save'), the clock."""

    plan: Plan
    several: bool  # more than one axis: file names get the unit
    yes: bool
    ask: Callable[[int, str], bool]
    written: dict[int, dict[str, tuple[Entry, int]]] = field(default_factory=dict)
    clock: Clock = field(default_factory=RealClock)
    force: bool = False  # `run --force`: files may be replaced
    # A safety line before a step moves (the dead-man bound, NO DEAD-MAN): shown even where step lines are quiet.
    safety: Callable[[str], None] = field(default=lambda _line: None)

    def wrote(self, drive: Drive, entry: Entry, raw: int) -> None:
        self.written.setdefault(drive.unit, {})[entry.code] = (entry, raw)

    def path(self, text: str, unit: int) -> Path:
        """A file named in the plan, resolved as plan_files.resolve does it (and checked, before the run, by
        plan_files.plan_files)."""
        return resolve(self.plan, text, unit, self.several)

    def may_replace(self, step_says: bool = False) -> bool:
        """Whether a file the step writes may replace an existing one: the step, the plan or --force says so."""
        return step_says or self.plan.overwrite or self.force


@dataclass(frozen=True)
class Outcome:
    """What a step did: one line for the log, and the data for the report."""

    detail: str
    data: dict[str, Any] = field(default_factory=dict)


class StepType:
    """One kind of plan step. validate() and describe() see only the profile (nothing is read or written);
    run() acts on one drive."""

    name: ClassVar[str]

    def validate(self, step: Step, profile: Profile) -> None:
        """Raise UsageError for anything wrong with the step on this profile."""
        self.describe(step, profile)

    def describe(self, step: Step, profile: Profile) -> str:
        """What the step would do (the dry run's line); raises as validate() does."""
        raise NotImplementedError

    def files(self, step: Step, profile: Profile) -> list[FileUse]:
        """The files the step writes or reads, as named in the plan (checked before anything runs)."""
        return []

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        raise NotImplementedError


def no_argument(step: Step) -> None:
    if step.arg is not None:
        raise UsageError(f"'{step.name}' takes no argument (got {step.arg!r})")


def number_in(value: Any, what: str, low: float, high: float) -> float:
    """A number from a plan (YAML true/false are not numbers), within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        raise UsageError(f"{what} must be a number {low:g}..{high:g}, got {value!r}")
    return float(value)
