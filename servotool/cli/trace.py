"""`servotool trace`: triggered capture at the fastest rate the line allows."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import typer

from servotool.cli.common import boosted, drive, resolved
from servotool.cli.render import info, out
from servotool.clock import utc_now
from servotool.connection import Resolved
from servotool.errors import ServoError, UsageError
from servotool.ops.monitor import resolve_entries
from servotool.ops.trace import TRIGGER_FORMS, Capture, Tracer, Window, parse_trigger
from servotool.ops.trace_file import capture_json, capture_table, check_writable, trace_csv, write_trace


def about_lines(res: Resolved, detail: str, baud: int | None = None) -> list[str]:
    """The CSV header's '# ' lines: the drive, the line settings (baud: the speed it ran at, where a boost raised
    it), what was captured, when."""
    s, p = res.settings, res.profile
    line = s.line.describe() if baud in (None, s.line.baud) else f"{baud} {s.line.describe().split()[1]} (raised)"
    return [
        f"servotool trace: {p.model} (profile {p.id}) unit {res.unit}",
        f"line: {s.port}, {line}, timeout {s.timeout:g} s",
        detail,
        f"started: {utc_now().isoformat(timespec='seconds')}",
    ]


def _about(res: Resolved, tracer: Tracer, expr: str | None, window: Window, baud: int) -> list[str]:
    size = f"{window.samples} samples" if window.samples is not None else f"{window.duration_s:g} s"
    trig = (
        f"{tracer.trigger.describe()} ({expr}), {window.pre_share * 100:g} % before it"
        if tracer.trigger is not None
        else "none (free run)"
    )
    return about_lines(
        res, f"trigger: {trig}; capture {size}; {tracer.sampler.requests_per_sample} request(s) per sample", baud
    )


def trace(
    ctx: typer.Context,
    codes: list[str] = typer.Argument(None, help="Entries to capture (default: the profile's key monitors)."),
    trigger: str = typer.Option(
        None, "--trigger", "-t", help=f"Start the capture when {TRIGGER_FORMS}. Default: at once."
    ),
    samples: int = typer.Option(None, "--samples", "-n", help="Samples per capture (default 500 unless --duration)."),
    duration: float = typer.Option(None, "--duration", "-d", help="Seconds per capture (instead of --samples)."),
    pre: float = typer.Option(20.0, "--pre", help="Share of the capture from before the trigger, in % (0..99)."),
    repeat: int = typer.Option(1, "--repeat", help="Captures to take, each on a new trigger edge; 0: until Ctrl-C."),
    timeout: float = typer.Option(
        None,
        "--timeout",
        help="Give up when the trigger has not fired this many seconds after arming (default: wait until Ctrl-C).",
    ),
    output: Path = typer.Option(None, "--output", "-o", help="Write the CSV here (default: stdout)."),
    force: bool = typer.Option(False, "--force", help="With --output: replace an existing file."),
    as_json: bool = typer.Option(False, "--json", help="The captures as JSON on stdout."),
    plot: bool = typer.Option(False, "--plot", help="Draw each capture in the terminal."),
) -> None:
    """Capture entries around a trigger, as fast as the line allows; report the rate and jitter achieved."""
    window = Window(samples if samples is not None or duration is not None else 500, duration, pre / 100.0)
    if repeat < 0:
        raise UsageError(f"bad --repeat {repeat}: the number of captures, 0 for until Ctrl-C")
    if timeout is not None and not timeout > 0:
        raise UsageError(f"bad --timeout {timeout:g}: must be seconds > 0")
    if output is not None:
        check_writable(output, force)
    res = resolved(ctx)
    entries = resolve_entries(res.profile, codes or [])
    trig = parse_trigger(res.profile, trigger) if trigger else None
    captures: list[Capture] = []
    interrupted = False
    with drive(ctx) as d, boosted(ctx, [d], "the trace") as line:
        tracer = Tracer(d, entries, trig, window, repeat=repeat, timeout_s=timeout)
        about = _about(res, tracer, trigger, window, line.baud)
        info(f"trace armed: {about[2].removeprefix('trigger: ')}")
        try:
            for cap in tracer.run():
                captures.append(cap)
                info(f"capture {cap.index}: {cap.timing.describe()}")
                if plot:
                    _plot(cap, tracer, res)
        except KeyboardInterrupt:  # the captures taken are written, then exit 130 as for any Ctrl-C
            info(f"trace stopped by Ctrl-C after {len(captures)} capture(s)")
            interrupted = True
        except ServoError:
            if captures:
                _write(captures, tracer, about, output, force, as_json, plot)
            raise
    _write(captures, tracer, about, output, force, as_json, plot)
    if interrupted:
        raise typer.Exit(130)
    if not captures:
        b, e = tracer.buffer, tracer.trigger.entry if tracer.trigger else None
        seen = f"; {e.code} ranged {b.low:g}..{b.high:g} {e.unit}" if e is not None and b.low <= b.high else ""
        raise ServoError(f"no capture: the trigger did not fire{' within --timeout' if tracer.timed_out else ''}{seen}")


def _write(
    captures: list[Capture],
    tracer: Tracer,
    about: list[str],
    output: Path | None,
    force: bool,
    as_json: bool,
    plot: bool,
) -> None:
    if not captures:
        return
    if output is not None:
        write_trace(output, captures, tracer.entries, about, replace=force)
        info(f"wrote {sum(len(c.t) for c in captures)} samples in {len(captures)} capture(s) to {output}")
    if as_json:
        print(json.dumps({"about": about, "captures": [capture_json(c, tracer.entries) for c in captures]}))
    elif output is None and not plot:
        sys.stdout.write(trace_csv(captures, tracer.entries, about))


def _plot(cap: Capture, tracer: Tracer, res: Resolved) -> None:
    from servotool.report.terminal import terminal_chart

    chart = terminal_chart(
        capture_table(cap, tracer.entries),
        min(out.width, 120),
        max(14, out.height - 4),
        f"capture {cap.index} ({res.profile.model})",
        color=sys.stdout.isatty(),
    )
    print(chart.text)
    if chart.left_out:
        info(f"not drawn (no room): {', '.join(chart.left_out)}")
