"""`servotool run PLAN.yaml`: a scripted commissioning plan."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import typer

from servotool.cli.common import notice_for, state
from servotool.cli.messages import error_text
from servotool.cli.render import Verbosity, emit_json, info, notice, out, safety, trace_frame, warn
from servotool.commission.plan import Plan, load_plan
from servotool.commission.runner import Report, Runner
from servotool.commission.steps import validate
from servotool.connection import Resolved, merge, options_from, resolve
from servotool.errors import ServoError, UsageError
from servotool.session import open_drives
from servotool.words import count


def run(
    ctx: typer.Context,
    plan_file: Path = typer.Argument(..., help="The plan (YAML)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate the whole plan and show the steps; touch nothing."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Skip operator prompts."),
    continue_on_error: bool = typer.Option(
        False, "--continue-on-error", help="Run the remaining steps after a failed one."
    ),
    report: Path = typer.Option(None, "--report", help="Report file (default: PLAN.report.json next to the plan)."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
) -> None:
    """Validate a commissioning plan completely, then run its steps on one or more axes."""
    plan = load_plan(plan_file)
    cli_opts = state(ctx).options
    resolved = resolve(merge(cli_opts, options_from(plan.options, str(plan_file))))
    units = _units(plan, cli_opts.unit, resolved.unit)
    lines = validate(plan, resolved.profile)
    if dry_run:
        _show_dry_run(plan, plan_file, resolved, units, lines, as_json)
        return
    # Everything that can be known before the first write is checked now.
    if not yes and any(st.name == "prompt" for st in plan.steps) and not sys.stdin.isatty():
        raise UsageError("the plan has operator prompts: run it in a terminal or pass --yes")
    report_path = _report_path(plan_file, report)
    several = len(units) > 1

    def ask(unit: int, question: str) -> bool:
        return typer.confirm(f"unit {unit}: {question}" if several else question, default=False, err=True)

    with open_drives(
        resolved, units, trace=trace_frame if Verbosity.level > 0 else None, notice=notice_for(ctx)
    ) as drives:
        runner = Runner(
            plan,
            drives,
            yes=yes,
            continue_on_error=continue_on_error,
            ask=ask,
            log=info,
            word=lambda exc: error_text(exc, cli_opts),
            safety=safety,
        )
        rep = Report(report_path, runner, profile=resolved.profile.id, port=resolved.settings.port, units=units)
        if rep.previous is not None:
            prev = rep.head["previous_run"]
            warn(
                f"the last run of this plan (pid {prev['pid']}) ended without finishing, after "
                f"{count(prev['steps_done'], 'step')}: its report {report_path} said 'running'; this run replaces it"
            )
        rep.write("running")
        runner.after_step = lambda: rep.write("running")
        ok: bool | None = None
        try:
            runner.check_units()
            runner.back_up(notice)
            ok = runner.run()
        except ServoError:
            ok = False
            raise
        finally:  # also when interrupted: the report says what was written and where it stopped
            data = rep.final(ok)
    if as_json:
        emit_json(data)
    else:
        out.print(
            f"plan {'completed' if ok else 'FAILED'}: {sum(r.ok for r in runner.results)}/"
            f"{len(runner.results)} steps ok; report {report_path}",
            markup=False,
        )
    if not ok:
        failures = [r for r in runner.results if not r.ok]
        if Verbosity.level < 0 and not as_json:  # --quiet hid the step lines: a failure is an error, shown
            for r in failures:
                notice(f"FAIL unit {r.unit} {r.step.where()}: {r.detail}")
        raise typer.Exit(int(failures[0].data.get("exit_code", 1)) if failures else 1)


def _units(plan: Plan, given: int | None, default: int) -> list[int]:
    """The axes to run: the plan's (or the resolved unit), narrowed to one of them by --unit."""
    if given is None or not plan.units:
        return plan.units or [default]
    if given not in plan.units:
        raise UsageError(f"--unit {given} is not among the plan's units {plan.units}")
    return [given]


def _show_dry_run(
    plan: Plan, plan_file: Path, resolved: Resolved, units: list[int], lines: list[str], as_json: bool
) -> None:
    if as_json:
        emit_json(
            {
                "plan": str(plan_file),
                "dry_run": True,
                "ok": True,
                "profile": resolved.profile.id,
                "units": units,
                "steps": [
                    {"step": st.index + 1, "line": st.line, "name": st.name, "would": line.split(": ", 1)[1]}
                    for st, line in zip(plan.steps, lines, strict=True)
                ],
            }
        )
        return
    out.print(
        f"plan {plan_file}: {count(len(plan.steps), 'step')} on {resolved.profile.model} unit(s) "
        f"{', '.join(map(str, units))}; valid. Would run:",
        markup=False,
    )
    for line in lines:
        out.print("  " + line, markup=False)


def _report_path(plan_file: Path, report: Path | None) -> Path:
    """--report, else PLAN.report.json beside the plan; refused before anything runs if it cannot be written."""
    path = report or plan_file.with_suffix(".report.json")
    if str(path).startswith("-"):
        raise UsageError(f"--report '{path}' looks like an option, not a file name")
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
        raise UsageError(f"cannot write the report into {path.parent}: no such folder or not writable")
    return path
