"""Plain tables and lines written without rich come out exactly as rich prints them where no style shows."""

from __future__ import annotations

import io
import random

import pytest
from rich.console import Console

from servotool.cli import render
from servotool.cli.grid import Grid


def _rich(obj: object, width: int, **kwargs: object) -> str:
    screen = io.StringIO()
    Console(file=screen, width=width, highlight=False, emoji=False, force_terminal=False).print(obj, **kwargs)
    return screen.getvalue()


WORDS = ["Pn004", "Load inertia ratio", "250", "%", "", " spaced ", "0: off, 1: on", ":smile:", "a" * 30, "-1.5"]


def _grid(rng: random.Random) -> Grid:
    heads = rng.sample(["Code", "Name", "Value", "Unit", "Default", "", "Min", "Address"], rng.randint(1, 6))
    t = render.table(*heads, title=rng.choice([None, "", "DSX7E unit 1", "t" * 12]))
    for _ in range(rng.randint(1, 5)):
        t.add_row(*(rng.choice(WORDS) for _ in heads))
    return t


@pytest.mark.parametrize("seed", range(100))
def test_a_plain_table_is_drawn_as_rich_draws_it(seed):
    rng = random.Random(seed)
    t = _grid(rng)
    width = rng.choice([40, 80, render.UNLIMITED])
    drawn = t.plain(width)
    if drawn is None:  # only for a cell with spaces at an end, a table to fit or a title wider than it
        spaced = any(c != c.strip() for col in t.columns for c in col._cells)
        assert spaced or render.fit(t, width) is not t or len(t.title or "") > 0
        return
    assert drawn == _rich(t.rich(), width)


def test_cells_rich_would_change_go_to_rich():
    for cell in ("[bold]x[/bold]", "tab\there", "two\nlines", "wide 中文", "µs"):
        t = render.table("Code", "Name")
        t.add_row("Pn004", cell)
        assert t.plain(render.UNLIMITED) is None


@pytest.mark.parametrize(
    "text", ["servotool: SIMULATED drive (unit 1)", "a [bold]b[/bold] c", "x:smile:y", "", "two\nlines", "µs 中文"]
)
def test_a_plain_line_is_printed_as_rich_prints_it(text, monkeypatch):
    screen = io.StringIO()
    monkeypatch.setattr("sys.stderr", screen)
    stream = render._Stream(stderr=True)
    stream.print(text, markup=False)
    assert stream._console is None  # no rich needed
    assert screen.getvalue() == _rich(text, render.UNLIMITED, markup=False, soft_wrap=True)
