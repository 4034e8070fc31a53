"""Backup, diff, restore and factory reset on the simulated drive."""

from __future__ import annotations

import pytest
import yaml

from servotool.profile import load_profile
from servotool.sim.device import SimulatedDrive

CHANGES = {"Pn003": "20", "Pn004": "600", "Pn025": "250.0", "Pn026": "260.0", "Pn027": "5000", "Pn036": "90",
           "Pn043": "400", "Pn044": "30", "Pn047": "150", "Pn100": "45.0", "Pn101": "30.0", "Pn102": "25.0",
           "Pn106": "50.0", "Pn120": "-5.0", "Pn128": "1.00", "Pn417": "5", "Pn512": "300", "Pn513": "150",
           "Pn514": "80", "Pn008": "20000"}


@pytest.fixture
def env(cli, tmp_path, monkeypatch):
    monkeypatch.setenv("SERVOTOOL_BACKUP_DIR", str(tmp_path / "auto"))
    return cli


def values(cli, *codes: str) -> dict[str, object]:
    r = cli("--port", "sim", "param", "get", *codes, "--json")
    assert r.code == 0, r.err
    return {d["code"]: d["raw"] for d in r.json()}


def test_round_trip_and_second_restore_writes_nothing(env, tmp_path):
    cli = env
    assert cli("--port", "sim", "param", "set", *[f"{k}={v}" for k, v in CHANGES.items()]).code == 0
    changed = values(cli, *CHANGES)
    f = tmp_path / "drive.yaml"
    r = cli("--port", "sim", "param", "backup", "-o", str(f), "--json")
    assert r.code == 0, r.err
    assert r.json()["entries"] >= 100
    assert cli("--port", "sim", "param", "reset", "--yes").code == 0
    assert values(cli, "Pn004")["Pn004"] == 250
    r = cli("--port", "sim", "param", "diff", str(f), "--json")
    assert {d["code"] for d in r.json()["differences"]} == set(CHANGES)
    r = cli("--port", "sim", "param", "restore", str(f), "--yes", "--json")
    assert r.code == 0, r.err
    assert set(r.json()["written"]) == set(CHANGES)
    assert (tmp_path / "auto").exists() and r.json()["auto_backup"].startswith(str(tmp_path / "auto"))
    assert values(cli, *CHANGES) == changed
    r = cli("--port", "sim", "-v", "param", "restore", str(f), "--yes", "--json")
    assert r.json()["written"] == [] and ">> 01 06" not in r.err and ">> 01 10" not in r.err


def test_fault_midway_rolls_back_to_the_automatic_backup(env, tmp_path, sim_dir):
    cli = env
    f = tmp_path / "target.yaml"
    cli("--port", "sim", "param", "set", "Pn100=45", "Pn101=30", "Pn512=300")
    assert cli("--port", "sim", "param", "backup", "-o", str(f)).code == 0
    cli("--port", "sim", "param", "reset", "--yes")
    before = values(cli, "Pn100", "Pn101", "Pn512")
    SimulatedDrive(load_profile("dsx7e"), 1).inject_fault("Pn101")
    r = cli("--port", "sim", "param", "restore", str(f), "--yes")
    assert r.code == 1
    assert "restore stopped at Pn101" in r.err and "rolled back" in r.err
    assert values(cli, "Pn100", "Pn101", "Pn512") == before
    auto = sorted((tmp_path / "auto").glob("*before-restore.yaml"))[-1]
    r = cli("--port", "sim", "param", "diff", str(auto), "--json")
    assert r.json()["differences"] == []


@pytest.mark.parametrize(("edit", "message"), [
    (lambda t: t[: len(t) // 2], "not a valid backup|incomplete"),
    (lambda t: t.replace("Pn004: 250", "Pn004: fast"), "is not an integer"),
    (lambda t: t.replace("Pn004: 250", "Pn004: 250\n  Pn999: 1").replace("display:", "display:\n  Pn999: x"),
     "unknown parameter Pn999"),
    (lambda t: t.replace("Pn004: 250", "Pn004: 99"), "outside 100..12000"),
    (lambda t: t.replace("model: DSX7E", "model: OTHER"), "not of this DSX7E"),
    (lambda t: t.replace("Pn004: 250", "Pn004: 260"), "checksum mismatch"),
    (lambda t: "[1, 2", "not a valid backup"),
])
def test_bad_files_are_refused_before_any_write(env, tmp_path, edit, message):
    import re

    cli = env
    f = tmp_path / "b.yaml"
    assert cli("--port", "sim", "param", "backup", "-o", str(f)).code == 0
    cli("--port", "sim", "param", "set", "Pn100=45")
    f.write_text(edit(f.read_text()))
    r = cli("--port", "sim", "-v", "param", "restore", str(f), "--yes")
    assert r.code == 2, r.err
    assert re.search(message, r.err), r.err
    assert ">> 01 06" not in r.err and ">> 01 10" not in r.err        # not a single write frame
    assert values(cli, "Pn100")["Pn100"] == 450


def test_backup_never_overwrites_and_diff_two_files(env, tmp_path):
    cli = env
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    assert cli("--port", "sim", "param", "backup", "-o", str(a)).code == 0
    r = cli("--port", "sim", "param", "backup", "-o", str(a))
    assert r.code == 2 and "exists" in r.err
    cli("--port", "sim", "param", "set", "Pn100=45", "Pn008=20000")
    cli("--port", "sim", "param", "backup", "-o", str(b))
    r = cli("param", "diff", str(a), str(b), "--json")
    assert r.code == 0, r.err
    rows = {d["code"]: d for d in r.json()["differences"]}
    assert set(rows) == {"Pn100", "Pn008"} and rows["Pn008"]["effect"] == "power_cycle"
    r = cli("param", "diff", str(b), "--changed-from-default", "--json")
    assert {d["code"] for d in r.json()["differences"]} == {"Pn100", "Pn008"}


def test_axis_specific_entries_are_skipped_unless_named(env, tmp_path):
    cli = env
    cli("--port", "sim", "param", "set", "Pn610=5")
    f = tmp_path / "b.yaml"
    cli("--port", "sim", "param", "backup", "-o", str(f))
    cli("--port", "sim", "param", "set", "Pn610=1")
    r = cli("--port", "sim", "param", "restore", str(f), "--yes", "--json")
    assert r.json()["written"] == [] and r.json()["skipped"][0]["code"] == "Pn610"
    r = cli("--port", "sim", "param", "restore", str(f), "--yes", "--json", "--include", "Pn610")
    assert r.json()["written"] == ["Pn610"]
    r = cli("--port", "sim", "param", "restore", str(f), "--json", "--only", "gain", "--dry-run")
    assert r.code == 0 and r.json()["changes"] == []
    data = yaml.safe_load(f.read_text())
    assert data["values"]["Pn610"] == 5 and data["display"]["Pn100"].startswith("32.0")
