"""`servotool monitor`: live values of monitor entries."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import typer
from rich.live import Live

from servotool.cli.common import drive
from servotool.cli.render import info, out, table
from servotool.monitor import CsvLog, Monitor, resolve_entries


def _fmt(value: float, decimals: int) -> str:
    return f"{value:.{decimals}f}" if value not in (float("inf"), float("-inf")) else ""


def _view(mon: Monitor):
    from servotool.codec import decimals

    t = table("Code", "Name", "Value", "Unit", "Min", "Max", "Trend",
              title=f"{mon.drive.profile.model} unit {mon.drive.unit}: {mon.samples} samples, "
                    f"{mon.achieved_rate:.1f} Hz")
    for s in mon.series.values():
        d = decimals(s.entry)
        t.add_row(s.entry.code, s.entry.name, _fmt(s.last, d), s.entry.unit, _fmt(s.low, d), _fmt(s.high, d),
                  s.sparkline())
    return t


def monitor(
    ctx: typer.Context,
    codes: list[str] = typer.Argument(None, help="Entries to watch (default: the profile's key monitors)."),
    rate: float = typer.Option(10.0, "--rate", "-r", help="Samples per second (0 = as fast as the link allows)."),
    duration: float = typer.Option(None, "--duration", "-d", help="Stop after this many seconds (default: Ctrl-C)."),
    csv_file: Path = typer.Option(None, "--csv", help="Also log timestamped samples to this CSV file."),
    as_json: bool = typer.Option(False, "--json", help="One JSON object per sample, one per line."),
    once: bool = typer.Option(False, "--once", help="Print one sample and exit."),
) -> None:
    """Watch live values with units, min/max and a trend; report the sample rate achieved."""
    if rate < 0:
        raise typer.BadParameter("must be >= 0", param_hint="--rate")
    if duration is not None and duration <= 0:
        raise typer.BadParameter("must be > 0", param_hint="--duration")
    with drive(ctx) as d:
        entries = resolve_entries(d.profile, codes or [])
        mon = Monitor(d, entries)
        log = CsvLog(csv_file, entries) if csv_file else None
        live_view = not (as_json or once) and sys.stdout.isatty()
        try:
            samples = mon.run(rate, duration, samples=1 if once else None)
            if live_view:
                with Live(_view(mon), console=out, refresh_per_second=8, transient=False) as live:
                    for s in samples:
                        if log:
                            log.write(s)
                        live.update(_view(mon))
            else:
                for s in samples:
                    if log:
                        log.write(s)
                    if as_json:
                        print(json.dumps({"t": round(s.t, 4), "time": s.wall.isoformat(timespec="milliseconds"),
                                          "values": s.values}), flush=True)
                if once and not as_json:
                    out.print(_view(mon))
                elif not as_json:
                    out.print(_view(mon))
        except KeyboardInterrupt:
            pass
        finally:
            if log:
                log.close()
    if not once:
        info(f"{mon.samples} samples in {mon.elapsed:.2f} s: {mon.achieved_rate:.1f} samples/s achieved")

