"""`servotool scan`: find the drives on a bus and the profile each one matches."""

from __future__ import annotations

from dataclasses import replace

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from servotool.cli.common import JSON_OPT, state
from servotool.cli.render import Verbosity, emit_json, err, info, out, table
from servotool.ops import scan as scanning
from servotool.words import count


def _split(values: list[str] | None) -> list[str]:
    return [v for item in values or [] for v in item.replace(" ", "").split(",") if v]


def scan(
    ctx: typer.Context,
    port: str = typer.Option(None, "--port", "-p", help="Port to scan (default: the global --port)."),
    units: str = typer.Option(None, "--units", help="Unit ids, e.g. 1-10 or 1-5,17 (default: 1-247)."),
    baud: list[str] = typer.Option(
        None,
        "--baud",
        "-b",
        help="Baud rate(s) to try, e.g. 9600 or 9600,19200 "
        "(default: each profile's factory setting, then 9600..115200).",
    ),
    fmt: list[str] = typer.Option(
        None,
        "--format",
        help="Frame format(s) to try: 8N1, 8E1, 8O1, 8N2 (default: each profile's factory format, then all four).",
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Find drives on a bus (line settings x unit ids, --timeout each, default 0.1 s) and the profile each matches."""
    options = state(ctx).options
    if port:
        options = replace(options, port=port)
    try:
        bauds = [int(b) for b in _split(baud)] or None
    except ValueError:
        raise typer.BadParameter(f"'{','.join(baud)}' is not a list of baud rates", param_hint="--baud") from None
    plan = scanning.plan(options, units, bauds, _split(fmt) or None)
    settings = f"{len(plan.settings)} line setting(s)" if plan.settings else "RTU over TCP"
    info(f"scanning {plan.port}: {len(plan.units)} unit id(s) x {settings}, {plan.timeout:g} s per silent id")
    show = err.is_terminal and not as_json and Verbosity.level >= 0
    columns = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=err, transient=True, disable=not show) as progress:
        task = progress.add_task("scanning", total=None)

        def advance(done: int, total: int, setting: str) -> None:
            progress.update(task, completed=done, total=total, description=f"scanning {setting}")

        result = scanning.scan(
            plan.port, plan.units, plan.settings, plan.profiles, timeout=plan.timeout, progress=advance
        )
    if as_json:
        emit_json(result.as_json())
        return
    _render(result)


def _render(result: scanning.ScanResult) -> None:
    if not result.found:
        out.print(f"no drive answered on {result.port} ({result.probes} probes, {result.seconds:.1f} s)", markup=False)
    else:
        # One port per scan (named in the title): its column goes first when 80 columns are too few for all.
        t = table(
            "Port",
            "Baud",
            "Format",
            "Unit",
            "Model",
            "Firmware",
            "Likely profile",
            title=f"{count(len(result.found), 'drive')} on {result.port}",
            drop=("Port", "Firmware", "Format"),
        )
        for f in result.found:
            best = f.best
            model = (
                "?"
                if best is None
                else best.profile.model + (f" (code {best.model})" if best.model is not None else "")
            )
            firmware = (
                ""
                if best is None or best.firmware is None
                else f"{best.firmware} ({best.profile.identity.firmware})"
                if best.profile.identity
                else ""
            )
            t.add_row(
                f.port,
                str(f.line.baud) if f.line else "-",
                scanning.line_format_text(f.line) if f.line else "-",
                str(f.unit),
                model,
                firmware,
                best.profile.id if best else "unknown (no profile matches)",
            )
        out.print(t)
    if result.unusable:
        skipped = ", ".join(scanning.line_format_text(s, baud=True) for s, _e in result.unusable)
        info(f"not tried, the port cannot do them: {skipped} ({result.unusable[0][1]})")
    if result.noise:
        ids = ", ".join(f"{u} ({k})" for _s, u, k in result.noise[:8]) + (" ..." if len(result.noise) > 8 else "")
        info(
            f"garbled or stray answers at {len(result.noise)} id(s): {ids} - a wrong baud rate or format, noise, "
            f"or a drive slower than the timeout (try --timeout)"
        )
