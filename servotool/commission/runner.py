"""Running a validated plan on one or more axes, and its report."""

from __future__ import annotations

import json
import os
import socket
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.clock import Clock, RealClock, utc_now
from servotool.commission.plan import Plan, Step
from servotool.commission.step_type import RunContext
from servotool.commission.steps import step_type
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError, UsageError
from servotool.files import process_alive, write_atomic

READ_ONLY_STEPS = ("expect", "backup", "wait", "prompt")
STALE = "interrupted (process ended without finishing)"


@dataclass
class StepResult:
    step: Step
    unit: int
    ok: bool
    detail: str
    seconds: float
    data: dict[str, Any] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return {
            "step": self.step.index + 1,
            "line": self.step.line,
            "name": self.step.name,
            "unit": self.unit,
            "ok": self.ok,
            "detail": self.detail,
            "seconds": round(self.seconds, 3),
            **self.data,
        }


class Runner:
    """Runs a validated plan on open drives, step by step (each on every axis it names), by its step type."""

    def __init__(
        self,
        plan: Plan,
        drives: list[Drive],
        *,
        yes: bool,
        continue_on_error: bool,
        ask: Callable[[int, str], bool],
        log: Callable[[str], None],
        word: Callable[[ServoError], str] = str,
        clock: Clock | None = None,
        safety: Callable[[str], None] | None = None,
        force: bool = False,
    ) -> None:
        """word turns a failed step's error into its report line (the CLI adds fix commands); safety shows a
        motion step's dead-man bound before it moves (never quiet); force: files the plan writes may replace
        existing ones (`run --force`)."""
        self.plan, self.drives = plan, drives
        self.clock = clock or RealClock()
        self.continue_on_error, self.log, self.word = continue_on_error, log, word
        self.context = RunContext(plan, len(drives) > 1, yes, ask, {d.unit: {} for d in drives}, self.clock, force)
        if safety is not None:
            self.context.safety = safety
        self.results: list[StepResult] = []
        self.current: Step | None = None  # the step running (or the last one run)
        self.auto_backups: dict[int, str] = {}
        self.after_step: Callable[[], None] = lambda: None  # e.g. rewrite the report

    def check_units(self) -> None:
        """Every axis answers before the first step writes anything."""
        for d in self.drives:
            probe = d.profile.role("alarm_code") or next(e for e in d.profile.entries if e.readable)
            try:
                d.read_entries([probe])
            except DeviceError as exc:
                raise DeviceError(f"unit {d.unit} does not answer, so nothing was run: {exc}") from None

    def check_setup(self) -> None:
        """The drive settings every motion step needs, on every axis, before anything is written: one UsageError
        naming each step, axis and setting (worded as a failed step would be), not a refusal after the plan has
        already written and moved."""
        from servotool.commission.prerequisites import unmet

        problems = [
            f"{step.where()}, unit {d.unit}: {self.word(exc)}" for d in self.drives for step, exc in unmet(self.plan, d)
        ]
        if problems:
            raise UsageError("nothing was run: " + "; ".join(problems))

    def back_up(self, notice: Callable[[str], None]) -> None:
        """An automatic backup of every axis before the plan's first write (a plan that only reads needs none)."""
        from servotool.ops.backup import auto_backup

        if not writes_to_drives(self.plan):
            return
        for d in self.drives:
            self.auto_backups[d.unit] = str(auto_backup(d, "before-plan"))
            notice(f"automatic backup of unit {d.unit} before the plan: {self.auto_backups[d.unit]}")

    def run(self) -> bool:
        for step in self.plan.steps:
            self.current = step
            kind = step_type(step)
            for drive in self.drives:
                if step.units and drive.unit not in step.units:
                    continue
                t0 = self.clock.now()
                try:
                    outcome = kind.run(step, drive, self.context)
                    detail, data, ok = outcome.detail, outcome.data, True
                except ServoError as exc:
                    detail, ok = self.word(exc), False
                    # the error's own facts where it has them (a rollback: why, and the step check that failed)
                    data = {"error": type(exc).__name__, "exit_code": exc.exit_code, **getattr(exc, "facts", {})}
                result = StepResult(step, drive.unit, ok, detail, self.clock.now() - t0, data)
                self.results.append(result)
                self.after_step()
                self.log(f"{'ok  ' if ok else 'FAIL'} unit {drive.unit} {step.where()}: {detail}")
                if not ok and not self.continue_on_error:
                    return False
        return all(r.ok for r in self.results)


def writes_to_drives(plan: Plan) -> bool:
    """Whether a step may write to a drive (and the run takes an automatic backup of every axis first)."""
    return not all(s.name in READ_ONLY_STEPS for s in plan.steps)


def read_report(path: Path) -> dict[str, Any] | None:
    """A plan report as written, None when there is none (or it is not a report). A report still `running` whose
    process is gone from this host (kill -9, power loss) says so: its status becomes STALE and ok false."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or "status" not in data:
        return None
    pid = data.get("pid")
    if (
        data["status"] == "running"
        and data.get("host") == socket.gethostname()
        and isinstance(pid, int)
        and not isinstance(pid, bool)
        and process_alive(pid) is False
    ):
        data = {**data, "status": STALE, "ok": False}
    return data


class Report:
    """The run's report file: written when the run starts (`running`, with the process id and host, so a run
    killed outright is told from one under way), rewritten atomically after every step, and ending `ok`, `failed
    at step N` or `interrupted at step N`, so a killed run never leaves an older report's verdict behind.

    `previous` is the report this run replaces when that run ended without finishing (its status STALE)."""

    def __init__(self, path: Path, runner: Runner, *, profile: str, port: str, units: list[int]) -> None:
        self.path, self.runner = path, runner
        self.head: dict[str, Any] = {
            "plan": str(runner.plan.path),
            "profile": profile,
            "port": port,
            "units": units,
            "pid": os.getpid(),
            "host": socket.gethostname(),
        }
        old = read_report(path)
        self.previous = old if old is not None and old["status"] == STALE else None
        if self.previous is not None:
            steps = self.previous.get("steps")
            self.head["previous_run"] = {
                "status": STALE,
                "pid": self.previous.get("pid"),
                "updated": self.previous.get("updated"),
                "steps_done": len(steps) if isinstance(steps, list) else 0,
            }
        self.t0 = runner.clock.now()

    def write(self, status: str) -> dict[str, Any]:
        from servotool import __version__

        r = self.runner
        stamp = utc_now(r.clock).astimezone().strftime("%Y-%m-%dT%H:%M:%S%z")
        report = {
            **self.head,
            "status": status,
            "ok": status == "ok",
            "tool_version": __version__,
            "seconds": round(r.clock.now() - self.t0, 2),
            "auto_backups": r.auto_backups,
            "finished" if status != "running" else "updated": stamp,
            "steps": [x.as_json() for x in r.results],
        }
        try:
            write_atomic(self.path, json.dumps(report, indent=2, default=str) + "\n")
        except OSError as exc:
            raise UsageError(f"cannot write report {self.path}: {exc.strerror or exc}") from None
        return report

    def final(self, ok: bool | None) -> dict[str, Any]:
        """ok None: interrupted (Ctrl-C, a terminate signal)."""
        r = self.runner
        where = r.current.index + 1 if r.current is not None else 0
        if ok is None:
            return self.write(f"interrupted at step {where}" if where else "interrupted before step 1")
        if ok:
            return self.write("ok")
        failed = next((x for x in r.results if not x.ok), None)
        if failed is None and r.current is None:
            return self.write("failed before step 1")
        return self.write(f"failed at step {failed.step.index + 1 if failed else where}")
