"""Every line of normal output, stderr included, fits 80 columns, and a long line is broken between words, not in
one (issue 33: at 80 columns stderr broke mid-word): representative commands run at COLUMNS=80."""

from __future__ import annotations

import pytest
from rich.cells import cell_len

from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive

NARROW = {"COLUMNS": "80"}
WIDE = {"COLUMNS": "1000"}


def _fits(text: str) -> None:
    for line in text.splitlines():
        assert cell_len(line) <= 80, f"{cell_len(line)} columns: {line!r}\n{text}"


def _words(text: str) -> list[str]:
    return text.split()


COMMANDS = [
    ("--port", "sim", "param", "get", "Pn004", "Pn101", "Un000"),
    ("--port", "sim", "param", "list", "-g", "gain"),
    ("--port", "sim", "param", "set", "Pn101=20", "Pn027=3000"),
    ("--port", "sim", "param", "diff", "--factory"),
    ("--port", "sim", "monitor", "--once"),
    ("--port", "sim", "-P", "sd25", "monitor", "--once"),
    ("--port", "sim", "monitor", "--io", "--once"),
    ("--port", "sim", "-P", "is620p", "monitor", "--io", "--once"),
    ("--port", "sim", "-P", "sd25", "monitor", "--io", "--once"),
    ("--port", "sim", "-P", "sdc", "monitor", "--io", "--once"),
    ("--port", "sim", "alarm"),
    ("--port", "sim", "alarm", "history"),
    ("--port", "sim", "jog", "--speed", "300", "--time", "0.3"),
    ("--port", "sim", "-P", "sdc", "jog", "--speed", "100", "--time", "1"),  # refused: its setup, said in full
    ("--port", "sim", "-P", "sd25", "jog", "--speed", "100", "--time", "1"),  # refused: no dead-man
    ("--port", "sim", "param", "get", "Pn4O4"),  # unknown code: suggestions
    ("--port", "sim", "param", "set", "Pn027=30000"),  # out of range
    ("profiles", "list"),
    ("profiles", "show", "sdc"),
    ("sim", "show"),
    ("--port", "sim", "tune", "inertia", "--yes", "--rigidity", "14"),
]


@pytest.mark.parametrize("args", COMMANDS, ids=" ".join)
def test_every_line_fits_80_columns(cli, args):
    r = cli(*args, env=NARROW)
    assert "Traceback" not in r.err, r.err
    _fits(r.out)
    _fits(r.err)


def _alarm(sim_dir) -> None:
    sim_drive = build_drive(load_profile("dsx7e"), 1)
    with sim_drive.session():
        sim_drive.firmware.trip("overload")
        sim_drive.bank.save()


@pytest.mark.parametrize(
    "args",
    [
        ("--port", "sim", "-P", "sdc", "jog", "--speed", "100", "--time", "1"),
        ("--port", "sim", "param", "get", "Pn4O4"),
        ("--port", "sim", "alarm"),
        ("--port", "sim", "alarm", "history"),
        ("--port", "sim", "-P", "is620p", "monitor", "--io", "--once"),
        ("--port", "sim", "param", "get", "Pn004"),
    ],
    ids=" ".join,
)
def test_long_lines_break_between_words(cli, sim_dir, args):
    """The same output at 80 columns and unwrapped has the same words: nothing was cut inside one."""
    _alarm(sim_dir)
    narrow, wide = cli(*args, env=NARROW), cli(*args, env=WIDE)
    assert narrow.code == wide.code, (narrow.err, wide.err)
    assert _words(narrow.err) == _words(wide.err)
    _fits(narrow.err)
    if "┃" not in narrow.out:  # a table wraps inside its cells; plain lines must keep their words
        assert _words(narrow.out) == _words(wide.out)
    assert any(cell_len(line) > 80 for line in (wide.out + wide.err).splitlines()), "nothing to wrap here"


def test_nothing_to_list_is_a_line_not_an_empty_table(cli):
    r = cli("--port", "sim", "param", "list", "--changed")
    assert r.code == 0, r.err
    assert r.out == "DSX7E unit 1: no entry differs from its factory default (108 entries read)\n"
    assert cli("--port", "sim", "param", "list", "--changed", "--json").json() == []
