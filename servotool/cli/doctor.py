"""`servotool doctor`: link health of one drive (round trips, echo, errors and retries, request rate, adapter)."""

from __future__ import annotations

from dataclasses import replace

import typer
from rich.progress import Progress

from servotool.cli.common import JSON_OPT, state
from servotool.cli.render import Verbosity, emit_json, err, out
from servotool.ops import doctor as health


def doctor(
    ctx: typer.Context,
    port: str = typer.Option(None, "--port", "-p", help="Port (default: the global --port)."),
    unit: int = typer.Option(None, "--unit", "-u", help="Unit id (default: the global --unit, the profile's, 1)."),
    count: int = typer.Option(50, "--count", "-n", help="Requests to send."),
    as_json: bool = JSON_OPT,
) -> None:
    """Link health: round trips, echo, errors and retries, request rate, the USB adapter's latency.

    Round-trip time (min/median/max), echo, error and retry rate over --count requests, the request rate achieved
    against the line settings' theoretical one, and the USB adapter's latency timer (Linux).
    """
    options = state(ctx).options
    options = replace(options, port=port or options.port, unit=unit if unit is not None else options.unit)
    settings, unit_id, profile = health.link_settings(options)
    show = err.is_terminal and not as_json and Verbosity.level >= 0
    with Progress(console=err, transient=True, disable=not show) as progress:
        task = progress.add_task(f"{count} requests to unit {unit_id}", total=count)
        report = health.check(settings, unit_id, profile, count, progress=lambda n: progress.update(task, completed=n))
    if as_json:
        emit_json(report.as_json())
        return
    for line in _lines(report):
        out.print(line, markup=False)


def _lines(h: health.Health) -> list[str]:
    where = f"{h.port} ({h.line.describe()})" if h.line else f"{h.port} (RTU over TCP)"
    lines = [f"link: {where}, unit {h.unit}, {h.count} reads of {h.registers} register(s) at address {h.address}"]
    rtt = h.rtt_ms()
    lines.append(
        "round trip: no answer"
        if rtt is None
        else f"round trip: min {rtt['min']:.1f} ms, median {rtt['median']:.1f} ms, max {rtt['max']:.1f} ms"
        + (f" ({h.exceptions} exception answers)" if h.exceptions else "")
    )
    lines.append(
        "echo: "
        + {
            True: "detected (the adapter repeats what is sent; it is skipped)",
            False: "none",
            None: "not determined (no answer)",
        }[h.echo]
    )
    lines.append(
        f"errors: {h.failures} of {h.count} requests failed ({100 * h.failures / h.count:.1f} %); "
        f"retries: {h.retries} extra frames ({100 * h.retries / h.count:.1f} %)"
    )
    theory = h.theoretical_rate
    lines.append(
        f"rate: {h.achieved_rate:.0f} requests/s"
        + (f" of {theory:.0f}/s the line allows at {h.line.describe()} (wire time only)" if theory and h.line else "")
    )
    if h.latency is None:
        lines.append("adapter: no USB-serial latency timer found" + (" (RTU over TCP)" if h.line is None else ""))
    elif h.latency.ms > 1:
        lines.append(
            f"adapter: latency timer {h.latency.ms} ms ({h.latency.path}): replies wait up to that long in "
            f"the adapter; lower it with 'echo 1 | sudo tee {h.latency.path}'"
        )
    else:
        lines.append(f"adapter: latency timer {h.latency.ms} ms ({h.latency.path}): fine")
    return lines
