"""Every table fits 80 columns with readable names; piped output without a terminal is not wrapped."""

from __future__ import annotations

import io

import pytest
from rich.cells import cell_len
from rich.table import Table

from servotool.cli import render
from servotool.model.loader import load_profile

NARROW = {"COLUMNS": "80"}


def _widest(text: str) -> int:
    return max((cell_len(line) for line in text.splitlines()), default=0)


def _name_width(text: str) -> int | None:
    """Width of the Name column, read from the table's header row."""
    for line in text.splitlines():
        cells = line.split("┃")
        for cell in cells:
            if cell.strip() == "Name":
                return cell_len(cell) - 2
    return None


TABLES = [
    ("profiles", "list"),
    ("profiles", "show", "dsx7e"),
    ("profiles", "show", "sd25"),
    ("profiles", "show", "is620p"),
    ("profiles", "show", "sdc"),
    ("profiles", "show", "is620p", "--unverified"),
    ("--port", "sim", "param", "list"),
    ("--port", "sim", "-P", "is620p", "param", "list", "--class", "Un"),
    ("--port", "sim", "param", "get", "Pn004", "Pn101", "Po001"),
    ("--port", "sim", "monitor", "--once"),
    ("--port", "sim", "alarm", "history"),
    ("sim", "show"),
    ("-P", "is620p", "param", "find", "speed"),
    ("--port", "sim", "raw", "read", "0x2004"),
    ("--port", "sim", "param", "diff", "--factory"),
]


@pytest.mark.parametrize("args", TABLES, ids=" ".join)
def test_every_table_fits_80_columns_with_readable_names(cli, args):
    r = cli(*args, env=NARROW)
    assert r.code in (0, 2), r.err
    assert _widest(r.out) <= 80, r.out
    name = _name_width(r.out)
    if name is not None and _widest(r.out) == 80:  # a table at the limit: its names were not squeezed
        assert name >= render.NAME_MIN, r.out


def test_diff_and_restore_plan_fit_80_columns(cli, tmp_path):
    backup = tmp_path / "axis.yaml"
    assert cli("--port", "sim", "param", "backup", "-o", str(backup)).code == 0
    cli("--port", "sim", "param", "set", "Pn101=25", "Pn008=20000", "Pn027=3000")
    for args in (("param", "diff", str(backup)), ("param", "restore", str(backup), "--dry-run")):
        r = cli("--port", "sim", *args, env=NARROW)
        assert r.code == (1 if args[1] == "diff" else 0), r.err  # a diff that finds differences exits 1
        assert _widest(r.out) <= 80 and "Pn101" in r.out
        assert (_name_width(r.out) or 99) >= render.NAME_MIN or _widest(r.out) < 80, r.out


def test_piped_without_a_terminal_is_not_wrapped(cli):
    r = cli("profiles", "list", env={"COLUMNS": ""})
    for pid in ("dsx7e", "sd25", "is620p", "sdc"):
        description = load_profile(pid).description
        assert any(description in line for line in r.out.splitlines()), r.out


def _wide_table() -> Table:
    t = render.table("Code", "Name", "Address", "Type", "Value", "Unit", "Effect")
    t.add_row("Pn004", "Load inertia ratio of the motor and machine", "8196 (0x2004)", "u16", "250", "%", "immediate")
    return t


def test_fit_drops_the_least_useful_columns_first():
    fitted = render.fit(_wide_table(), 60)
    assert isinstance(fitted, Table)
    assert [str(c.header) for c in fitted.columns] == ["Code", "Name", "Value", "Unit", "Effect"]


def test_a_table_too_wide_for_any_layout_becomes_one_block_per_row():
    t = render.table("Code", "Name", "Value", drop=())
    t.add_row("Pn004", "Load inertia ratio", "12345678901234567890123456789")
    fitted = render.fit(t, 40)
    assert not isinstance(fitted, Table)
    console = render.FittingConsole(width=40, record=True, file=io.StringIO())
    console.print(fitted)
    text = console.export_text()
    assert "Pn004" in text and "Name: Load inertia ratio" in text and _widest(text) <= 40


def test_a_table_that_fits_is_left_alone():
    t = render.table("Code", "Name")
    t.add_row("Pn004", "Load inertia ratio")
    assert render.fit(t, 80) is t


def test_progress_shows_a_bar_with_time_left_on_a_terminal_only(monkeypatch):
    screen = io.StringIO()
    monkeypatch.setattr(render, "err", render.Console(file=screen, force_terminal=True, width=80))
    with render.progress("reading parameters", 10) as advance:
        advance(5)
    assert "reading parameters" in screen.getvalue()
    monkeypatch.setattr(render, "err", render.Console(file=io.StringIO(), force_terminal=False))
    with render.progress("reading", 10) as advance:  # piped: nothing, and advancing is harmless
        advance(3)


def test_the_gains_table_names_entries_not_roles_and_fits_80_columns(cli):
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--rigidity", "14", "--travel", "12", env=NARROW)
    assert r.code == 0, r.err
    assert "Speed loop gain" in r.out and "speed_loop_gain" not in r.out
    assert _widest(r.out) <= 80 and (_name_width(r.out) or 0) >= render.NAME_MIN


def test_the_levels_tried_by_tune_gains_are_a_table_at_80_columns(cli):
    r = cli("--port", "sim", "tune", "gains", "--yes", "--from", "16", "--to", "17", env=NARROW)
    assert r.code == 0, r.err
    assert _widest(r.out) <= 80
    assert any(line.startswith("│ 16") for line in r.out.splitlines()), r.out  # a row, not a block per level
