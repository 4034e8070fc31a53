"""Everyday features: param find, diff --factory, CSV for spreadsheets (and back), raw registers."""

from __future__ import annotations

import csv
import io
import os
import subprocess
import sys

import pytest


def test_find_searches_codes_names_and_descriptions_without_a_drive(cli):
    r = cli("-P", "is620p", "param", "find", "speed", "loop", "--json")
    assert r.code == 0, r.err
    codes = [row["code"] for row in r.json()]
    assert "H08-00" in codes and all("speed loop" in row["name"].lower() for row in r.json())
    r = cli("-P", "is620p", "param", "find", "H0800", "--json")
    assert [row["code"] for row in r.json()] == ["H08-00"]
    r = cli("param", "find", "monitor", "speed", "--port", "sim", "--json")  # Un entries too
    assert "Un000" in [row["code"] for row in r.json()]
    r = cli("-P", "sd25", "param", "find", "CCW", "--json")  # in Po001's description only
    assert [row["code"] for row in r.json()] == ["Po001"]


def test_diff_factory_compares_the_drive_with_its_defaults(cli):
    r = cli("--port", "sim", "param", "diff", "--factory")
    assert r.code == 0 and r.out.startswith("no differences")
    cli("--port", "sim", "param", "set", "Pn101=25")
    r = cli("--port", "sim", "param", "diff", "--factory", "--json")
    assert r.code == 1  # they differ: exit 1, for scripts (issue 35)
    assert r.json()["differences"] == [
        {
            "code": "Pn101",
            "name": "Speed loop gain",
            "unit": "Hz",
            "effect": "unknown",
            "a": 25.0,
            "b": 18.0,
            "value_unverified": "unit/scale not printed (unit column empty); inferred",
        }
    ]
    assert cli("--port", "sim", "param", "diff").code == 2  # neither a file nor --factory


def test_list_csv_is_a_spreadsheet_table(cli):
    cli("--port", "sim", "param", "set", "Pn101=25")
    r = cli("--port", "sim", "param", "list", "--group", "gain", "--csv")
    rows = list(csv.DictReader(io.StringIO(r.out)))
    pn101 = next(row for row in rows if row["code"] == "Pn101")
    assert pn101["value"] == "25.0" and pn101["unit"] == "Hz" and pn101["changed"] == "yes" and pn101["raw"] == "250"


def test_a_csv_backup_edited_in_a_spreadsheet_restores(cli, tmp_path):
    path = tmp_path / "axis.csv"
    r = cli("--port", "sim", "param", "backup", "-o", str(path))
    assert r.code == 0 and "108 parameters saved" in r.out
    lines = path.read_text().splitlines()
    assert lines[0].startswith("servotool parameter backup,profile=dsx7e")
    path.write_text(
        "\n".join(line.replace("Pn101,Speed loop gain,18.0", "Pn101,Speed loop gain,22.5") for line in lines) + "\n"
    )
    r = cli("--port", "sim", "param", "restore", str(path), "--yes")
    assert r.code == 0, r.err
    assert "1 parameter restored" in r.out and "no checksum" in r.err
    assert "interrupted" not in r.err  # the restore's own journal record is not taken for a dead one's
    assert cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"] == 22.5


def test_a_bad_csv_value_is_refused_with_its_line_before_any_write(cli, tmp_path):
    path = tmp_path / "axis.csv"
    cli("--port", "sim", "param", "backup", "-o", str(path))
    path.write_text(path.read_text().replace("Pn101,Speed loop gain,18.0", "Pn101,Speed loop gain,fast"))
    r = cli("--port", "sim", "param", "restore", str(path), "--yes")
    assert r.code == 2 and "line" in r.err and "Pn101" in r.err


def test_raw_read_and_write_by_address(cli):
    r = cli("--port", "sim", "raw", "write", "0x2004=300")
    assert r.code == 0 and "Pn004" in r.out and "verified" in r.out
    r = cli("--port", "sim", "raw", "read", "8196", "--json")
    assert r.json() == [{"address": 8196, "value": 300, "signed": 300, "entry": "Pn004"}]
    assert cli("--port", "sim", "raw", "write", "0x2004=70000").code == 2
    assert cli("--port", "sim", "raw", "read", "banana").code == 2


def _complete(cli, words: str) -> list[str]:
    r = cli(
        env={"_SERVOTOOL_COMPLETE": "complete_bash", "COMP_WORDS": words, "COMP_CWORD": str(len(words.split()) - 1)}
    )
    return r.out.split()


def test_shell_completion_of_codes_groups_and_profiles(cli):
    assert "H08-00" in _complete(cli, "servotool -P is620p param get H08-0")
    assert _complete(cli, "servotool -P s") == ["sd25", "sdc"]
    assert "gain" in _complete(cli, "servotool param list --group g")
    assert "Pn101=" in _complete(cli, "servotool param set Pn10")


def _stderr_on_a_terminal(*args: str) -> str:
    """Run servotool with stderr on a pseudo-terminal (where progress bars show); what it wrote there."""
    pty = pytest.importorskip("pty")
    master, slave = pty.openpty()
    subprocess.run(
        [sys.executable, "-m", "servotool", *args],
        stdout=subprocess.DEVNULL,
        stderr=slave,
        env={**os.environ, "COLUMNS": "100"},
        timeout=60,
        check=False,
    )
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:  # the other end is closed: all read
            break
        if not chunk:
            break
        seen += chunk
    os.close(master)
    return seen.decode(errors="replace")


def test_diff_and_restore_show_progress_while_reading_the_drive(cli, tmp_path):
    backup = tmp_path / "axis.yaml"
    cli("--port", "sim", "param", "backup", "-o", str(backup))
    cli("--port", "sim", "param", "set", "Pn101=25")
    assert "reading the drive" in _stderr_on_a_terminal("--port", "sim", "param", "diff", "--factory")
    shown = _stderr_on_a_terminal("--port", "sim", "param", "restore", str(backup), "--yes")
    assert "automatic backup, then writing" in shown and "109/109" in shown  # 108 read, 1 written


def test_raw_write_on_a_real_port_asks_first(cli):
    from servotool.model.loader import load_profile
    from servotool.sim.firmware import build_drive
    from servotool.sim.server import EmbeddedSim

    line = EmbeddedSim([build_drive(load_profile("dsx7e"), 1, persist=False)])
    try:
        r = cli("--port", line.port, "-P", "dsx7e", "raw", "write", "0x2004=300", input="")
        assert r.code == 2 and "needs confirmation" in r.err and "Pn004" in r.err
        assert cli("--port", line.port, "-P", "dsx7e", "raw", "read", "0x2004", "--json").json()[0]["value"] == 250
        r = cli("--port", line.port, "-P", "dsx7e", "raw", "write", "0x2004=300", "--yes")
        assert r.code == 0 and "verified" in r.out
    finally:
        line.close()
