"""`servotool monitor --io`: each digital input and output with its level and assigned function, live."""

from __future__ import annotations

import sys
from typing import Any

from servotool.cli.render import emit_json_line, fit, out, table
from servotool.ops.monitor import Monitor, Sample
from servotool.ops.terminals import Levels, TerminalReader

TITLES = {"inputs": "inputs", "outputs": "outputs"}


def io_tables(reader: TerminalReader, levels: Levels) -> list[Any]:
    """One table per group: terminal, level, function (as the manual names it), what sets it, its logic, a note."""
    tables = []
    for group in reader.groups:
        rows = reader.assignments[group.direction]
        logic = any(a.logic for a in rows)
        heads = ["Terminal", "Level", "Function", "Set by", *(["Logic"] if logic else []), "Note"]
        t = table(*heads, title=f"{TITLES[group.direction]} ({group.monitor})", drop=("Note", "Logic", "Set by"))
        for a in rows:
            level = levels.of(group.direction)[a.terminal.name]
            cells = [a.terminal.name, "on" if level else "off", a.function, a.set_by]
            t.add_row(*cells, *([a.logic.split(" = ", 1)[-1]] if logic else []), a.terminal.note)
        tables.append(t)
    return tables


def footnotes(reader: TerminalReader) -> list[str]:
    """Why a function shown has no name, and what the manual leaves open about the groups and functions, once."""
    said: list[str] = []
    for group in reader.groups:
        rows = reader.assignments[group.direction]
        unnamed = sorted({a.number for a in rows if not a.named and a.number is not None})
        if unnamed:
            numbers = ", ".join(str(n) for n in unnamed)
            said.append(f"{group.direction} function {numbers}: {group.unlisted or 'not named in the manual'}")
        for text in [group.unverified, *(a.unverified for a in rows)]:
            if text and f"unverified: {text}" not in said:
                said.append(f"unverified: {text}")
    return said


def io_json(reader: TerminalReader, levels: Levels, sample: Sample | None = None) -> dict[str, object]:
    """One reading: every terminal with its level and function; with a sample, its time."""

    def rows(direction: str) -> list[dict[str, object]]:
        return [{**a.as_json(), "level": levels.of(direction)[a.terminal.name]} for a in reader.assignments[direction]]

    data: dict[str, object] = (
        {} if sample is None else {"t": round(sample.t, 4), "time": sample.wall.isoformat(timespec="milliseconds")}
    )
    for group in reader.groups:
        data[group.direction] = rows(group.direction)
        data[f"{group.direction}_monitor"] = group.monitor
        data[f"{group.direction}_unverified"] = group.unverified or None  # what the manual leaves open of them all
    return data


def _on(levels: Levels) -> str:
    on = [name for d in ("inputs", "outputs") for name, level in levels.of(d).items() if level]
    return "on: " + (" ".join(on) if on else "none")


def show_io(reader: TerminalReader, mon: Monitor, rate: float, duration: float | None, *, once: bool, as_json: bool):
    """Read the assignments once, then the levels: a live table on a terminal, else a line whenever they change
    (JSON: a line each sample), then the table; --once: one reading."""
    reader.read_assignments()
    samples = mon.run(rate, duration, samples=1 if once else None)
    live = not (as_json or once) and sys.stdout.isatty()
    levels: Levels | None = None
    if live:
        from rich.console import Group
        from rich.live import Live

        with Live(console=out, refresh_per_second=8, transient=False) as view:
            for s in samples:
                levels = reader.levels(s.values)
                view.update(Group(*(fit(t, out.width) for t in io_tables(reader, levels))))
    else:
        last = ""
        for s in samples:
            levels = reader.levels(s.values)
            if as_json:
                emit_json_line(io_json(reader, levels, s))
            elif not once and (line := _on(levels)) != last:
                print(f"{s.t:8.3f} s  {line}", flush=True)
                last = line
    if levels is None or as_json:
        return
    if not live:
        for t in io_tables(reader, levels):
            out.print(t)
    for text in footnotes(reader):
        out.print(text, markup=False)
