"""`servotool run PLAN.yaml`: a scripted commissioning plan."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import typer

from servotool import plan as plans
from servotool.cli.common import state
from servotool.cli.render import Verbosity, emit_json, info, notice, out, trace_frame
from servotool.connection import ConnectOptions, merge, open_drives, resolve
from servotool.errors import ServoError


def run(
    ctx: typer.Context,
    plan_file: Path = typer.Argument(..., help="The plan (YAML)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate the whole plan and show the steps; touch "
                                 "nothing."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Skip operator prompts."),
    continue_on_error: bool = typer.Option(False, "--continue-on-error", help="Run the remaining steps after a "
                                           "failed one."),
    report: Path = typer.Option(None, "--report", help="Report file (default: PLAN.report.json next to the plan)."),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
) -> None:
    """Validate a commissioning plan completely, then run its steps on one or more axes."""
    plan = plans.load_plan(plan_file)
    given = {k: v for k, v in plan.options.items() if k in ConnectOptions.__dataclass_fields__}
    opts = merge(state(ctx).options, ConnectOptions(**{k: (str(v) if k in ("port", "profile", "parity") else v)
                                                        for k, v in given.items()}))
    resolved = resolve(opts, need_port=not dry_run)
    units = plan.units or [resolved.unit]
    lines = plans.validate(plan, resolved.profile)
    if dry_run:
        if as_json:
            emit_json({"plan": str(plan_file), "dry_run": True, "units": units, "profile": resolved.profile.id,
                       "steps": lines})
        else:
            out.print(f"plan {plan_file}: {len(plan.steps)} steps on {resolved.profile.model} unit(s) "
                      f"{', '.join(map(str, units))}; valid. Would run:", markup=False)
            for line in lines:
                out.print("  " + line, markup=False)
        return
    t0 = time.monotonic()

    def ask(question: str) -> bool:
        if not sys.stdin.isatty():
            raise ServoError(f"prompt '{question}' needs an operator: run in a terminal or pass --yes")
        return typer.confirm(question, default=False)

    with open_drives(resolved, units, trace=trace_frame if Verbosity.level > 0 else None, notice=notice) as drives:
        runner = plans.Runner(plan, drives, yes=yes, continue_on_error=continue_on_error, ask=ask, log=info)
        ok = runner.run()
    report_path = report or plan_file.with_suffix(".report.json")
    data = plans.write_report(report_path, plan, runner.results, ok, time.monotonic() - t0)
    if as_json:
        emit_json(data)
    else:
        out.print(f"plan {'completed' if ok else 'FAILED'}: {sum(r.ok for r in runner.results)}/"
                  f"{len(runner.results)} steps ok; report {report_path}", markup=False)
    if not ok:
        failed = next(r for r in runner.results if not r.ok)
        raise typer.Exit(int(failed.data.get("exit_code", 1)))
