"""`servotool monitor`: live values of monitor entries."""

from __future__ import annotations

import sys
from collections import deque
from collections.abc import Iterator
from pathlib import Path

import typer
from rich.live import Live
from rich.table import Table
from rich.text import Text

from servotool.cli import complete
from servotool.cli.common import drive, resolved
from servotool.cli.render import emit_json_line, info, out, table
from servotool.cli.values import json_mark
from servotool.errors import UsageError
from servotool.model.codec import decimals
from servotool.ops.monitor import CsvLog, CsvMode, Monitor, Sample, check_duration, check_rate, resolve_entries
from servotool.ops.trace_file import Series, TimeTable
from servotool.words import count

PLOT_SAMPLES = 300  # the scrolling chart shows this many of the latest samples
PLOT_REFRESH_S = 0.2
TREND_MIN = 8  # a trend narrower than this says nothing: drop the column instead
NAME_FLOOR = 16  # the name keeps at least this much room (or its full length) before the trend gets any


def _fmt(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}" if value not in (float("inf"), float("-inf")) else ""


def _title(mon: Monitor) -> str:
    rate = mon.achieved_rate
    count = f"{mon.samples} sample{'' if mon.samples == 1 else 's'}"
    marked = any(mon.drive.profile.value_unverified(e) for e in mon.entries)
    return (
        f"{mon.drive.profile.model} unit {mon.drive.unit}: {count}"
        + (f", {rate:.1f} Hz" if rate is not None else "")
        + ("; * unit or scale unverified" if marked else "")
    )


def monitor_table(mon: Monitor, width: int) -> Table:
    """The monitor table, fitted to `width` columns: long names are cut with '…', the trend shrinks or goes."""
    rows = []
    for s in mon.series.values():
        d = decimals(s.entry)
        unit = s.entry.unit + ("*" if mon.drive.profile.value_unverified(s.entry) else "")  # the title says why
        rows.append([s.entry.code, s.entry.name, _fmt(s.last, d), unit, _fmt(s.low, d), _fmt(s.high, d)])
    heads = ["Code", "Name", "Value", "Unit", "Min", "Max"]
    natural = [max([len(h)] + [len(r[i]) for r in rows]) for i, h in enumerate(heads)]
    fixed = sum(natural) - natural[1]
    name_floor = min(natural[1], NAME_FLOOR)
    longest_trend = max((len(s.trend) for s in mon.series.values()), default=0)
    # Each column costs its text plus one padding space either side and one rule; the table one more rule.
    trend = min(longest_trend, width - fixed - name_floor - (3 * 7 + 1))
    show_trend = longest_trend >= 2 and (trend >= TREND_MIN or trend >= longest_trend)
    ncols = 7 if show_trend else 6
    t = table(*heads, *(["Trend"] if show_trend else []), title=_title(mon))
    name_col = t.columns[1]
    name_col.no_wrap, name_col.overflow = True, "ellipsis"
    name_col.max_width = max(4, width - fixed - (max(trend, len("Trend")) if show_trend else 0) - (3 * ncols + 1))
    for c in t.columns[2:]:
        c.no_wrap = True
    for r, s in zip(rows, mon.series.values(), strict=True):
        t.add_row(*r, *([s.sparkline(trend)] if show_trend else []))
    return t


def _sample_json(mon: Monitor, s: Sample) -> dict[str, object]:
    """One JSON line: each value rounded to its entry's resolution, with its unit (and, where the manual leaves
    its scale or meaning open, why)."""
    profile = mon.drive.profile
    values: dict[str, object] = {}
    for c, v in s.values.items():
        entry = mon.series[c].entry
        values[c] = {
            "value": round(v, decimals(entry)) if isinstance(v, float) else v,
            "unit": entry.unit,
            "value_unverified": json_mark(profile, entry),
        }
    return {"t": round(s.t, 4), "time": s.wall.isoformat(timespec="milliseconds"), "values": values}


def monitor_chart(mon: Monitor, history: deque[Sample], width: int, height: int) -> Text:
    """The latest samples as a chart: one panel per unit, one series per entry, a legend with the units."""
    from servotool.report.terminal import terminal_chart

    table = TimeTable(
        Path("monitor"),
        "elapsed_s",
        [s.t for s in history],
        [Series(e.code, e.unit, [float(s.values[e.code]) for s in history]) for e in mon.entries],
    )
    chart = terminal_chart(table, width, height - 1, _title(mon))
    rest = f"\nnot drawn (no room; name fewer entries): {', '.join(chart.left_out)}" if chart.left_out else ""
    return Text.from_ansi(chart.text + rest)


def _plain_line(mon: Monitor, s: Sample) -> str:
    """One sample as a line: what --plot prints when the output is not a terminal."""
    return f"{s.t:8.3f} s  " + "  ".join(
        f"{e.code} {s.values[e.code]:g}{' ' + e.unit if e.unit else ''}" for e in mon.entries
    )


def _plot_live(mon: Monitor, samples: Iterator[Sample], log: CsvLog | None) -> None:
    history: deque[Sample] = deque(maxlen=PLOT_SAMPLES)
    drawn = -float("inf")
    with Live(Text(""), console=out, auto_refresh=False, transient=False) as live:
        for s in samples:
            if log:
                log.write(s)
            history.append(s)
            if mon.clock.now() - drawn >= PLOT_REFRESH_S:
                live.update(monitor_chart(mon, history, min(out.width, 160), out.height - 1), refresh=True)
                drawn = mon.clock.now()
        live.update(monitor_chart(mon, history, min(out.width, 160), out.height - 1), refresh=True)


def _csv_mode(csv_file: Path | None, force: bool, append: bool) -> CsvMode:
    if force and append:
        raise UsageError("--force and --append exclude each other")
    if (force or append) and csv_file is None:
        raise UsageError(f"{'--force' if force else '--append'} only applies to --csv FILE")
    return "replace" if force else "append" if append else "new"


def _show(
    mon: Monitor,
    samples: Iterator[Sample],
    log: CsvLog | None,
    *,
    plot: bool,
    live_view: bool,
    lines: bool,
    as_json: bool,
) -> None:
    """Samples as they come: a live chart or table on a terminal, else a plain or JSON line each as it comes (a
    pipe sees them at once), then the table; lines: --json or --once. Each sample is also logged to the CSV."""
    if plot and live_view:
        _plot_live(mon, samples, log)
        return
    if live_view:
        with Live(monitor_table(mon, out.width), console=out, refresh_per_second=8, transient=False) as live:
            for s in samples:
                if log:
                    log.write(s)
                live.update(monitor_table(mon, out.width))
        return
    for s in samples:
        if log:
            log.write(s)
        if not lines:
            print(_plain_line(mon, s), flush=True)
        elif as_json:
            emit_json_line(_sample_json(mon, s))
    if not as_json and not (plot and not lines):
        out.print(monitor_table(mon, out.width))


def _monitor_io(
    ctx: typer.Context,
    codes: list[str] | None,
    rate: float,
    duration: float | None,
    *,
    once: bool,
    as_json: bool,
    others: tuple[Path | None, bool],
) -> None:
    """monitor --io: the terminals, live (cli/io_view.py)."""
    from servotool.cli.io_view import show_io
    from servotool.ops.terminals import TerminalReader

    if codes:
        raise UsageError("--io shows the drive's inputs and outputs: give no codes with it")
    if others[0] is not None or others[1]:
        raise UsageError("--io does not take --csv or --plot")
    if resolved(ctx).profile.io is None:
        TerminalReader.refuse(resolved(ctx).profile)
    interrupted = False
    with drive(ctx) as d:
        reader = TerminalReader(d)
        mon = Monitor(d, reader.monitors)
        try:
            show_io(reader, mon, rate, duration, once=once, as_json=as_json)
        except KeyboardInterrupt:
            interrupted = True
    if not once:
        info(f"{count(mon.samples, 'sample')} in {mon.elapsed:.2f} s")
    if interrupted:
        raise typer.Exit(130)


def monitor(
    ctx: typer.Context,
    codes: list[str] = typer.Argument(
        None, autocompletion=complete.codes, help="Entries to watch (default: the profile's key monitors)."
    ),
    rate: float = typer.Option(
        10.0,
        "--rate",
        "-r",
        help="Samples per second, > 0 (a rate the link cannot keep up "
        "with polls as fast as it can; the rate achieved is shown).",
    ),
    duration: float = typer.Option(None, "--duration", "-d", help="Stop after this many seconds (default: Ctrl-C)."),
    csv_file: Path = typer.Option(
        None, "--csv", help="Also log timestamped samples to this CSV file (a new file unless --force or --append)."
    ),
    force: bool = typer.Option(False, "--force", help="With --csv: replace an existing file."),
    append: bool = typer.Option(
        False, "--append", help="With --csv: add rows to an existing file with the same columns."
    ),
    as_json: bool = typer.Option(False, "--json", help="One JSON object per sample, one per line."),
    once: bool = typer.Option(False, "--once", help="Print one sample and exit."),
    plot: bool = typer.Option(
        False,
        "--plot",
        help="A scrolling chart instead of the table (one panel per unit); "
        "plain lines when the output is not a terminal.",
    ),
    io: bool = typer.Option(
        False,
        "--io",
        help="The digital inputs and outputs instead: each terminal's level and the function the drive's "
        "parameters assign it, as the manual names it.",
    ),
) -> None:
    """Watch live values with units, min/max and a trend; report the sample rate achieved."""
    check_rate(rate)
    check_duration(duration)
    if io:
        _monitor_io(ctx, codes, rate, duration, once=once, as_json=as_json, others=(csv_file, plot))
        return
    mode = _csv_mode(csv_file, force, append)
    # Everything the user typed is checked before the port is opened: codes against the profile, the CSV path.
    entries = resolve_entries(resolved(ctx).profile, codes or [])
    log = CsvLog(csv_file, entries, mode) if csv_file else None
    interrupted = False
    try:
        with drive(ctx) as d:
            mon = Monitor(d, resolve_entries(d.profile, codes or []))
            live_view = not (as_json or once) and sys.stdout.isatty()
            samples = mon.run(rate, duration, samples=1 if once else None)
            try:
                _show(mon, samples, log, plot=plot, live_view=live_view, lines=as_json or once, as_json=as_json)
            except KeyboardInterrupt:  # the samples so far are shown, then exit 130 as for any Ctrl-C
                interrupted = True
                if not (live_view or as_json or plot):
                    out.print(monitor_table(mon, out.width))
    finally:
        if log:
            log.close()
    if not once:
        rate_text = (
            f"{mon.achieved_rate:.1f} samples/s achieved"
            if mon.achieved_rate is not None
            else "too few samples to measure a rate"
        )
        info(f"{count(mon.samples, 'sample')} in {mon.elapsed:.2f} s: {rate_text}")
    if interrupted:
        raise typer.Exit(130)
