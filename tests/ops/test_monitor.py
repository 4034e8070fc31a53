"""`servotool monitor`: the view fits a terminal, bad options and codes fail before the port opens, CSV is safe."""

from __future__ import annotations

import csv

import pytest
from rich.console import Console

from servotool.cli.monitor import monitor_table
from servotool.connection import ConnectOptions, resolve
from servotool.ops.monitor import Monitor, default_entries
from servotool.session import open_drives

PROFILES = ["dsx7e", "sd25", "is620p", "sdc"]
NO_PORT = ("--port", "/dev/nonexistent", "--profile", "dsx7e")


def _render(mon: Monitor, width: int) -> list[str]:
    console = Console(width=width, record=True, force_terminal=True, color_system=None)
    console.print(monitor_table(mon, width))
    return console.export_text().splitlines()


def _polled(profile: str) -> Monitor:
    """A monitor of the profile's default entries with a full trend, polled from the simulated drive."""
    with open_drives(resolve(ConnectOptions(port="sim", profile=profile)), notice=lambda _m: None) as (d,):
        mon = Monitor(d, default_entries(d.profile))
        for _ in mon.run(1000, None, samples=40):
            pass
    return mon


@pytest.mark.parametrize("profile", PROFILES)
def test_live_view_fits_80_columns_with_a_trend(sim_dir, profile):
    mon = _polled(profile)
    lines = _render(mon, 80)
    assert max(len(line) for line in lines) <= 80
    assert len(lines) == len(mon.entries) + 5  # title, 3 header rules/row, bottom: no row wraps
    assert "Trend" in lines[2]
    first_row = lines[4]
    trend = first_row.rstrip(" │").rsplit("│", 1)[1].strip()
    assert 8 <= len(trend) < 40  # shrunk to the room left, not folded
    wide = _render(mon, 200)
    assert len(wide[4].rstrip(" │").rsplit("│", 1)[1].strip()) == 40


@pytest.mark.parametrize("profile", PROFILES)
def test_live_view_fits_80_columns_with_the_widest_values(sim_dir, profile):
    mon = _polled(profile)
    for s in mon.series.values():
        e = s.entry
        s.add((-(2 ** (16 * e.words - 1)) if e.signed else 2 ** (16 * e.words) - 1) * e.scale)
    lines = _render(mon, 80)
    assert max(len(line) for line in lines) <= 80
    assert len(lines) == len(mon.entries) + 5
    for e in mon.entries:  # values are never cut, names may be
        assert any(line.startswith(f"│ {e.code} ") for line in lines)


def test_once_shows_no_rate_for_a_single_sample(cli):
    r = cli("--port", "sim", "monitor", "--once")
    assert r.code == 0, r.err
    assert "1 sample" in r.out and "Hz" not in r.out and "Trend" not in r.out
    assert "samples/s" not in r.err


@pytest.mark.parametrize(
    "args",
    [
        ("--rate", "nan"),
        ("--rate", "inf"),
        ("--rate", "0"),
        ("--rate", "-5"),
        ("--duration", "nan"),
        ("--duration", "0"),
        ("--duration", "-1"),
        ("--duration", "inf"),
    ],
)
def test_bad_rate_or_duration_is_a_usage_error_before_the_port_opens(cli, args):
    r = cli(*NO_PORT, "monitor", *args)
    assert r.code == 2
    assert r.err.count("\n") == 1 and f"bad {args[0]} " in r.err
    assert "cannot open port" not in r.err


def test_unknown_code_is_reported_before_the_port_opens(cli):
    r = cli(*NO_PORT, "monitor", "Un000", "Un999")
    assert r.code == 2
    assert r.err.count("\n") == 1 and "unknown code 'Un999'" in r.err


def test_csv_refuses_an_existing_file_and_an_unwritable_path_before_the_port_opens(cli, tmp_path):
    old = tmp_path / "old.csv"
    old.write_text("precious\n")
    r = cli(*NO_PORT, "monitor", "--csv", str(old))
    assert r.code == 2 and r.err.count("\n") == 1 and "exists" in r.err and "--force" in r.err
    assert old.read_text() == "precious\n"
    r = cli(*NO_PORT, "monitor", "--csv", str(tmp_path / "no-such-dir" / "log.csv"))
    assert r.code == 2 and r.err.count("\n") == 1 and "cannot write" in r.err
    r = cli(*NO_PORT, "monitor", "--csv", str(old), "--append")  # another tool's file: other columns
    assert r.code == 2 and "cannot append" in r.err
    r = cli(*NO_PORT, "monitor", "--force")
    assert r.code == 2 and "--csv" in r.err


def test_csv_force_keeps_the_old_file_until_a_sample_replaces_it(cli, tmp_path):
    old = tmp_path / "old.csv"
    old.write_text("precious\n")
    r = cli(*NO_PORT, "monitor", "--csv", str(old), "--force")
    assert r.code == 1 and "cannot open port" in r.err
    assert old.read_text() == "precious\n"  # the failed run replaced nothing
    new = tmp_path / "new.csv"
    r = cli(*NO_PORT, "monitor", "--csv", str(new))
    assert r.code == 1 and not new.exists()  # and left no empty file behind
    r = cli("--port", "sim", "monitor", "Un000", "--once", "--csv", str(old), "--force")
    assert r.code == 0, r.err
    rows = list(csv.reader(old.open()))
    assert rows[0] == ["timestamp", "elapsed_s", "Un000 [rpm]"] and len(rows) == 2


def test_csv_append_adds_rows_under_one_header(cli, tmp_path):
    log = tmp_path / "log.csv"
    for _ in range(2):
        r = cli("--port", "sim", "monitor", "Un000", "Un045", "--once", "--csv", str(log), "--append")
        assert r.code == 0, r.err
    rows = list(csv.reader(log.open()))
    assert rows[0] == ["timestamp", "elapsed_s", "Un000 [rpm]", "Un045 [V]"]
    assert len(rows) == 3 and all(abs(float(row[3]) - 311) < 20 for row in rows[1:])  # DC bus near 311 V
    r = cli("--port", "sim", "monitor", "Un000", "--once", "--csv", str(log), "--append")
    assert r.code == 2 and "columns" in r.err
    assert len(list(csv.reader(log.open()))) == 3
