"""PNG charts through matplotlib, the optional `plot` extra: imported only when a chart is drawn, so start-up and
installs without it are untouched."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from servotool.errors import UsageError
from servotool.ops.trace_file import TimeTable
from servotool.report.terminal import by_unit

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# servotool is installed from its checkout (no package index has it): the extra is named on the checkout's path.
MISSING = "charts need matplotlib: in the servotool checkout, pip install '.[plot]' (or pip install matplotlib)"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def need_matplotlib() -> None:
    """UsageError (one line) when matplotlib is not installed; checked before anything is measured."""
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise UsageError(MISSING) from None


def new_figure(rows: int, width_in: float = 10.0, row_in: float = 2.6, sharex: bool = True) -> tuple[Figure, Any]:
    """A figure of `rows` stacked axes, drawn off-screen (no display needed)."""
    need_matplotlib()
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, max(3.0, row_in * rows + 0.8)), layout="constrained")
    axes = fig.subplots(rows, 1, sharex=sharex, squeeze=False)[:, 0]
    return fig, axes


def save(fig: Figure, path: Path) -> Path:
    """Write the figure as PNG; one clear line when the file cannot be written."""
    try:
        fig.savefig(path, format="png", dpi=100)
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None
    return path


def table_figure(table: TimeTable, title: str = "") -> Figure:
    """Any trace or monitor CSV: one panel per unit, one labelled line per column, trigger at t = 0 marked."""
    groups = by_unit(table.series)
    fig, axes = new_figure(len(groups))
    segments = table.segments()
    for ax, group in zip(axes, groups, strict=True):
        for s in group:
            for c, idx in segments:
                label = s.label + (f" #{c}" if len(segments) > 1 else "")
                idx = [i for i in idx if s.values[i] == s.values[i]]  # a column read less often: no NaN gaps
                ax.plot([table.t[i] for i in idx], [s.values[i] for i in idx], label=label, linewidth=1.2)
        ax.set_ylabel(group[0].unit or "value")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
        if table.capture and min(table.t) < 0 < max(table.t):
            ax.axvline(0.0, color="red", linestyle=":", linewidth=1)
    axes[-1].set_xlabel(f"{table.time_name.removesuffix('_s')} [s]")
    fig.suptitle(title or table.path.name)
    return fig
