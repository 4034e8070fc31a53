"""`servotool run PLAN.yaml`: a scripted commissioning plan."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from servotool.cli.common import boosted, drives_for, resolved_from, state
from servotool.cli.messages import error_text
from servotool.cli.render import Verbosity, emit_json, info, notice, out, safety, warn
from servotool.commission.plan import Plan, load_plan
from servotool.commission.plan_files import report_problem
from servotool.commission.prerequisites import motion_setup
from servotool.commission.runner import Report, Runner, writes_to_drives
from servotool.commission.steps import Checked, validate
from servotool.connection import Resolved, merge, options_from
from servotool.errors import ServoError, UsageError
from servotool.files import backup_dir
from servotool.words import count


def run(
    ctx: typer.Context,
    plan_file: Path = typer.Argument(..., help="The plan (YAML)."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate the whole plan and show the steps; touch nothing."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Skip operator prompts."),
    continue_on_error: bool = typer.Option(
        False, "--continue-on-error", help="Run the remaining steps after a failed one."
    ),
    report: Path = typer.Option(
        None, "--report", help="Report file (default: PLAN.report.json next to the plan, replaced by each run)."
    ),
    force: bool = typer.Option(
        False, "--force", help="Files the plan writes, and --report, may replace existing ones (as overwrite: true)."
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the report as JSON."),
) -> None:
    """Validate a commissioning plan completely, then run its steps on one or more axes."""
    plan = load_plan(plan_file)
    cli_opts = state(ctx).options
    resolved = resolved_from(merge(cli_opts, options_from(plan.options, str(plan_file))))
    units = _units(plan, cli_opts.unit, resolved.unit)
    # Everything that can be known before anything moves is checked now, the same for a dry run: every step
    # against the profile, every file the steps write or read, the report.
    report_path = _report_path(plan_file, report, force)
    checked = validate(plan, resolved.profile, units, force=force)
    if dry_run:
        _show_dry_run(plan, plan_file, resolved, units, checked, report_path, as_json)
        return
    if not yes and any(st.name == "prompt" for st in plan.steps) and not sys.stdin.isatty():
        raise UsageError("the plan has operator prompts: run it in a terminal or pass --yes")
    several = len(units) > 1

    def ask(unit: int, question: str) -> bool:
        return typer.confirm(f"unit {unit}: {question}" if several else question, default=False, err=True)

    long = any(st.name in LONG_STEPS for st in plan.steps)  # the automatic backup before the plan is one too
    with drives_for(ctx, resolved, units) as drives, boosted(ctx, drives, "the plan", allow=long, res=resolved):
        runner = Runner(
            plan,
            drives,
            yes=yes,
            continue_on_error=continue_on_error,
            ask=ask,
            log=info,
            word=lambda exc: error_text(exc, cli_opts),
            safety=safety,
            force=force,
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
            runner.check_setup()
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


# steps whose exchanges a raised line shortens (ops.boost)
LONG_STEPS = ("tune inertia", "tune score", "tune friction", "tune notch", "tune gain-switching", "backup", "restore")


def _units(plan: Plan, given: int | None, default: int) -> list[int]:
    """The axes to run: the plan's (or the resolved unit), narrowed to one of them by --unit."""
    if given is None or not plan.units:
        return plan.units or [default]
    if given not in plan.units:
        raise UsageError(f"--unit {given} is not among the plan's units {plan.units}")
    return [given]


def _show_dry_run(
    plan: Plan,
    plan_file: Path,
    resolved: Resolved,
    units: list[int],
    checked: Checked,
    report_path: Path,
    as_json: bool,
) -> None:
    autos = backup_dir() if writes_to_drives(plan) else None
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
                    for st, line in zip(plan.steps, checked.lines, strict=True)
                ],
                "files": [f.as_json() for f in checked.files],
                "report": str(report_path),
                "auto_backups": None if autos is None else {"units": units, "folder": str(autos)},
                "drive_setup": [a for r in motion_setup(plan, resolved.profile) for a in r.assignments()],
            }
        )
        return
    out.print(
        f"plan {plan_file}: {count(len(plan.steps), 'step')} on {resolved.profile.model} unit(s) "
        f"{', '.join(map(str, units))}; valid. Would run:",
        markup=False,
    )
    for line in checked.lines:
        out.print("  " + line, markup=False)
    out.print("Would write:", markup=False)
    if autos is not None:
        out.print(f"  an automatic backup of unit(s) {', '.join(map(str, units))} into {autos}/", markup=False)
    for f in (f for f in checked.files if f.writes):
        what = f"{f.kind}, step {f.step.index + 1}, unit {f.unit}" + ("; replaces the existing one" if f.exists else "")
        out.print(f"  {f.path}{'/' if f.kind == 'tune report' else ''} ({what})", markup=False)
    out.print(f"  {report_path} (the run's report)", markup=False)
    for f in (f for f in checked.files if not f.writes):
        out.print(f"Would read: {f.path} ({f.kind}, step {f.step.index + 1}, unit {f.unit})", markup=False)
    if needed := motion_setup(plan, resolved.profile):
        settings = ", ".join(", ".join(r.assignments()) for r in needed)
        out.print(f"Would check on each axis first, before anything moves: {settings} (host motion)", markup=False)


def _report_path(plan_file: Path, report: Path | None, force: bool) -> Path:
    """--report, else PLAN.report.json beside the plan (each run replaces it); refused before anything runs if it
    cannot be written, or if --report names a file that is not a plan report (without --force)."""
    path = report or plan_file.with_suffix(".report.json")
    if str(path).startswith("-"):
        raise UsageError(f"--report '{path}' looks like an option, not a file name")
    problem = report_problem(path, force=force or report is None)
    if problem is not None:
        raise UsageError(problem)
    return path
