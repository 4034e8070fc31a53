"""Running a validated plan on one or more axes, and its report."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.commission.plan import Plan, Step
from servotool.commission.step_type import RunContext
from servotool.commission.steps import step_type
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError, UsageError


@dataclass
class StepResult:
    step: Step
    unit: int
    ok: bool
    detail: str
    seconds: float
    data: dict[str, Any] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return {"step": self.step.index + 1, "line": self.step.line, "name": self.step.name, "unit": self.unit,
                "ok": self.ok, "detail": self.detail, "seconds": round(self.seconds, 3), **self.data}


class Runner:
    """Runs a validated plan on open drives, step by step (each on every axis it names), by its step type."""

    def __init__(self, plan: Plan, drives: list[Drive], *, yes: bool, continue_on_error: bool,
                 ask: Callable[[int, str], bool], log: Callable[[str], None],
                 word: Callable[[ServoError], str] = str) -> None:
        """word turns a failed step's error into its report line (the CLI adds fix commands)."""
        self.plan, self.drives = plan, drives
        self.continue_on_error, self.log, self.word = continue_on_error, log, word
        self.context = RunContext(plan, len(drives) > 1, yes, ask, {d.unit: {} for d in drives})
        self.results: list[StepResult] = []

    def check_units(self) -> None:
        """Every axis answers before the first step writes anything."""
        for d in self.drives:
            probe = d.profile.role("alarm_code") or next(e for e in d.profile.entries if e.readable)
            try:
                d.read_entries([probe])
            except DeviceError as exc:
                raise DeviceError(f"unit {d.unit} does not answer, so nothing was run: {exc}") from None

    def run(self) -> bool:
        for step in self.plan.steps:
            kind = step_type(step)
            for drive in self.drives:
                if step.units and drive.unit not in step.units:
                    continue
                t0 = time.monotonic()
                try:
                    outcome = kind.run(step, drive, self.context)
                    detail, data, ok = outcome.detail, outcome.data, True
                except ServoError as exc:
                    detail, data, ok = self.word(exc), {"error": type(exc).__name__, "exit_code": exc.exit_code}, False
                result = StepResult(step, drive.unit, ok, detail, time.monotonic() - t0, data)
                self.results.append(result)
                self.log(f"{'ok  ' if ok else 'FAIL'} unit {drive.unit} {step.where()}: {detail}")
                if not ok and not self.continue_on_error:
                    return False
        return all(r.ok for r in self.results)


def write_report(path: Path, plan: Plan, results: list[StepResult], ok: bool, seconds: float, *,
                 profile: str, port: str, units: list[int]) -> dict[str, Any]:
    from servotool import __version__

    report = {"plan": str(plan.path), "ok": ok, "profile": profile, "port": port, "units": units,
              "tool_version": __version__, "seconds": round(seconds, 2),
              "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "steps": [r.as_json() for r in results]}
    try:
        path.write_text(json.dumps(report, indent=2, default=str) + "\n")
    except OSError as exc:
        raise UsageError(f"cannot write report {path}: {exc.strerror}") from None
    return report
