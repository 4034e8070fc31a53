"""`servotool scan` and `servotool doctor` against simulated drives on one RTU-over-TCP line."""

from __future__ import annotations

import pytest

from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


@pytest.fixture
def line():
    sim = EmbeddedSim(
        [build_drive(load_profile("sdc"), 2, persist=False), build_drive(load_profile("is620p"), 4, persist=False)]
    )
    yield sim.port
    sim.close()


def test_scan_finds_two_drives_table_and_json(cli, line):
    r = cli("scan", "--port", line, "--units", "1-5")
    assert r.code == 0, r.err
    rows = [ln for ln in r.out.splitlines() if line in ln and "│" in ln]  # table rows, not the title
    assert len(rows) == 2 and "sdc" in rows[0] and "SDC" in rows[0] and "4007" in rows[0]
    assert "is620p" in rows[1] and "IS620P" in rows[1]
    r = cli("scan", "--port", line, "--units", "1-5", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert [(f["unit"], f["profile"]) for f in data["found"]] == [(2, "sdc"), (4, "is620p")]
    assert data["probes"] == 5


def test_scan_refuses_bad_ranges_in_one_line(cli, line):
    r = cli("scan", "--port", line, "--units", "0-9")
    assert r.code == 2 and len(r.err.strip().splitlines()) == 1 and "1..247" in r.err


def test_doctor_prints_its_figures_and_json(cli, line):
    r = cli("-P", "sdc", "doctor", "--port", line, "-u", "2", "--count", "10")
    assert r.code == 0, r.err
    for word in ("round trip: min", "median", "echo: none", "errors: 0 of 10", "rate:", "adapter:"):
        assert word in r.out, r.out
    r = cli("doctor", "--port", line, "-u", "4", "--count", "5", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["requests"] == 5 and data["answered"] == 5 and data["failures"] == 0 and data["echo"] is False
    assert data["rtt"]["min"] <= data["rtt"]["median"] <= data["rtt"]["max"] and data["rtt"]["unit"] == "ms"
    assert data["achieved_rate"]["value"] > 0 and data["theoretical_rate"] is None  # no line settings over tcp


def test_doctor_counts_failures_of_a_silent_unit(cli, line):
    r = cli("--timeout", "0.05", "--retries", "0", "doctor", "--port", line, "-u", "9", "--count", "3", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["failures"] == 3 and data["error_rate"] == 1.0 and data["rtt"] is None


def test_scan_table_fits_80_columns_one_row_per_drive(cli, line):
    r = cli("scan", "--port", line, "--units", "1-5", env={"COLUMNS": "80"})
    assert r.code == 0, r.err
    lines = r.out.splitlines()
    assert max(len(ln) for ln in lines) <= 80 and line in lines[0]  # the port is named in the title
    rows = [ln for ln in lines if "is620p" in ln]
    assert len(rows) == 1 and "IS620P" in rows[0]  # a table row, not a block per drive
