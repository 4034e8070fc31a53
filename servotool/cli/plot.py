"""`servotool plot`: draw a trace or monitor CSV as PNG or in the terminal."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from servotool.cli.render import info, out
from servotool.ops.trace_file import read_table


def plot(
    csv_file: Path = typer.Argument(..., help="A CSV from trace, monitor --csv or tune inertia --save-trace."),
    columns: list[str] = typer.Option(
        None, "--column", "-c", help="Only this column (code or 'CODE [unit]'); repeat for more."
    ),
    output: Path = typer.Option(
        None, "--output", "-o", help="Write a PNG here (needs servotool[plot]); default: draw in the terminal."
    ),
    title: str = typer.Option(None, "--title", help="Chart title (default: the file name)."),
) -> None:
    """Draw any servotool CSV: one panel per unit, one line per column."""
    if output is not None:
        from servotool.report.charts import need_matplotlib

        need_matplotlib()
    table = read_table(csv_file).select(columns or [])
    if output is not None:
        from servotool.report.charts import save, table_figure

        save(table_figure(table, title or ""), output)
        info(f"wrote {output}")
        return
    from servotool.report.terminal import terminal_chart

    chart = terminal_chart(
        table, min(out.width, 120), max(14, out.height - 2), title or csv_file.name, color=sys.stdout.isatty()
    )
    print(chart.text)
    if chart.left_out:
        info(f"not drawn (no room): {', '.join(chart.left_out)}; choose with --column")
