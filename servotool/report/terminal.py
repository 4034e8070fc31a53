"""Time series as a chart in the terminal (plotext): one panel per unit, one labelled series per column."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.ops.trace_file import Series, TimeTable

MIN_PANEL_ROWS = 7  # below this a panel shows no readable ticks


@dataclass(frozen=True)
class TerminalChart:
    text: str  # with colour codes; plotext's uncolorize() strips them
    left_out: list[str]  # series labels that found no room


def by_unit(series: list[Series]) -> list[list[Series]]:
    """Series grouped by unit, in the order of their first appearance."""
    groups: dict[str, list[Series]] = {}
    for s in series:
        groups.setdefault(s.unit, []).append(s)
    return list(groups.values())


def panel_rows(labels: int) -> int:
    """Rows a panel needs for its legend box (plotext leaves out a legend that does not fit) and its axes."""
    return max(MIN_PANEL_ROWS, 2 * labels + 6)


def terminal_chart(table: TimeTable, width: int, height: int, title: str = "", color: bool = True) -> TerminalChart:
    """Panels stacked to fit width x height cells; the panels that do not fit are named in left_out."""
    import plotext as plt

    groups = by_unit(table.series)
    segments = table.segments()
    fit = len(groups)
    while fit > 1 and height // fit < max(panel_rows(len(g) * len(segments)) for g in groups[:fit]):
        fit -= 1
    shown, rest = groups[:fit], groups[fit:]
    plt.terminal.limit(False, False)  # the caller knows the room (rich's console, a test); plotext need not guess
    fig = plt.figure
    fig.clear()
    fig.plot_size(max(40, width), max(MIN_PANEL_ROWS, height))
    if len(shown) > 1:
        fig.subplots(len(shown), 1)
    for row, group in enumerate(shown, start=1):
        ax = fig.subplot(row, 1) if len(shown) > 1 else fig
        ax.theme("simple" if color else "colorless")
        for s in group:
            for c, idx in segments:
                pairs = [(table.t[i], s.values[i]) for i in idx if s.values[i] == s.values[i]]  # NaN: no reading
                if pairs:
                    label = s.label + (f" #{c}" if len(segments) > 1 else "")
                    ax.draw(ax.signal([p[0] for p in pairs], [p[1] for p in pairs]).label(label).lines())
        ax.label(group[0].unit or "value", "y")
        if row == 1 and title:
            ax.title(title)
        if row == len(shown):
            ax.label(f"{table.time_name.removesuffix('_s')} [s]", "x")
    text = str(fig.build())
    return TerminalChart(text if color else plt.uncolorize(text), [s.label for g in rest for s in g])
