"""Time series as a chart in the terminal (plotext): one panel per unit, one labelled series per column."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.ops.trace_file import Series, TimeTable

MIN_PANEL_ROWS = 7       # below this a panel shows no readable ticks


@dataclass(frozen=True)
class TerminalChart:
    text: str                 # with colour codes; plotext's uncolorize() strips them
    left_out: list[str]       # series labels that found no room


def by_unit(series: list[Series]) -> list[list[Series]]:
    """Series grouped by unit, in the order of their first appearance."""
    groups: dict[str, list[Series]] = {}
    for s in series:
        groups.setdefault(s.unit, []).append(s)
    return list(groups.values())


def terminal_chart(table: TimeTable, width: int, height: int, title: str = "", color: bool = True) -> TerminalChart:
    """Panels stacked to fit width x height cells; the panels that do not fit are named in left_out."""
    import plotext as plt

    groups = by_unit(table.series)
    fit = max(1, min(len(groups), height // MIN_PANEL_ROWS))
    shown, rest = groups[:fit], groups[fit:]
    fig = plt.figure
    fig.clear()
    fig.plot_size(max(40, width), max(MIN_PANEL_ROWS, height))
    if len(shown) > 1:
        fig.subplots(len(shown), 1)
    for row, group in enumerate(shown, start=1):
        ax = fig.subplot(row, 1) if len(shown) > 1 else fig
        ax.theme("simple" if color else "colorless")
        for s in group:
            pairs = [(t, v) for t, v in zip(table.t, s.values, strict=True) if v == v]   # NaN: no reading
            if pairs:
                ax.draw(ax.signal([p[0] for p in pairs], [p[1] for p in pairs]).label(s.label).lines())
        ax.label(group[0].unit or "value", "y")
        if row == 1 and title:
            ax.title(title)
        if row == len(shown):
            ax.label(f"{table.time_name.removesuffix('_s')} [s]", "x")
    text = str(fig.build())
    return TerminalChart(text if color else plt.uncolorize(text), [s.label for g in rest for s in g])
