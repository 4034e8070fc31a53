"""Declarative, idempotent drive settings (issue 35 item 1): `param apply FILE` and ops.apply, judged with a plain
Modbus client against `sim serve`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from servotool.connection import ConnectOptions, resolve
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.ops import apply, changelog, desired
from servotool.session import open_drives
from servotool.sim.device import SimulatedDrive
from tests.ops.plain_client import read_registers

GOLDEN = """servotool_settings: 1
profile: sd25
save: true
parameters:
  Po101: 40.0        # Hz
  Po102: 25 ms
  Po110: 150
"""
ADDRESSES = {"Po101": 101, "Po102": 102, "Po110": 110}  # SD25's Po entries are at their number


def stored(port: str) -> dict[str, int]:
    return {code: read_registers(port, address)[0] for code, address in ADDRESSES.items()}


@pytest.fixture
def golden(tmp_path) -> Path:
    path = tmp_path / "golden.yaml"
    path.write_text(GOLDEN)
    return path


def test_check_writes_nothing_apply_changes_only_what_differs_and_a_second_run_is_unchanged(serve, cli, golden):
    port = serve("sd25")
    assert cli("--port", port, "param", "set", "Po110=150").code == 0  # one of three already as desired
    before = stored(port)
    r = cli("--port", port, "param", "apply", str(golden), "--check", "--json")
    assert r.code == 1, r.err  # something would change
    data = r.json()
    assert data["status"] == "would change" and data["check"] is True and data["changed"] is False
    assert [(s["code"], s["changed"]) for s in data["settings"]] == [("Po101", True), ("Po102", True), ("Po110", False)]
    assert data["settings"][0]["before"] == {"value": 60.0, "unit": "Hz"}
    assert data["settings"][0]["desired"] == {"value": 40.0, "unit": "Hz"} and data["settings"][0]["after"] is None
    assert stored(port) == before  # nothing written: read by pymodbus itself
    r = cli("--port", port, "param", "apply", str(golden), "--check", "--diff")
    assert r.code == 1 and "-Po101: 60.0 Hz\n+Po101: 40.0 Hz\n-Po102: 50.0 ms\n+Po102: 25.0 ms\n" in r.out, r.out
    r = cli("--port", port, "param", "apply", str(golden), "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["status"] == "changed" and data["verified"] is True and data["persisted"] is True
    assert data["settings"][1]["after"] == {"value": 25.0, "unit": "ms"}
    assert stored(port) == {"Po101": 400, "Po102": 250, "Po110": 150}
    r = cli("--port", port, "param", "apply", str(golden))
    assert r.code == 0 and "unchanged: 3 parameters already as desired" in r.out, r.out
    assert cli("--port", port, "param", "apply", str(golden), "--check").code == 0
    changes, _ = changelog.read()
    logged = [(c.data["code"], c.data["memory"], c.data["source"].split()[-2:]) for c in changes]
    assert logged == [
        ("Po110", "RAM", ["set", "Po110=150"]),
        ("Po101", "EEPROM", [str(golden), "--json"]),
        ("Po102", "EEPROM", [str(golden), "--json"]),
    ]


def test_a_write_the_drive_refuses_midway_is_rolled_back(serve, cli, golden, sim_dir):
    port = serve("sd25")
    SimulatedDrive(load_profile("sd25"), 1).inject_fault("Po110")  # Po101, Po102 go first (address order)
    before = stored(port)
    r = cli("--port", port, "param", "apply", str(golden))
    assert r.code == 1, r.err
    assert "apply stopped at Po110" in r.err and "rolled back" in r.err and "the drive is as it was" in r.err, r.err
    assert stored(port) == before
    assert not list((sim_dir.parent / "auto-backups" / "journal").glob("*.json"))  # no record left behind


def test_a_bad_value_or_another_profile_is_refused_before_anything_is_written(serve, cli, tmp_path):
    port = serve("sd25")
    before = stored(port)
    bad = tmp_path / "bad.yaml"
    bad.write_text(GOLDEN.replace("Po110: 150", "Po110: 999999"))
    r = cli("--port", port, "param", "apply", str(bad))
    assert r.code == 2 and "Po110" in r.err, r.err
    other = tmp_path / "other.yaml"
    other.write_text(GOLDEN.replace("profile: sd25", "profile: is620p"))
    r = cli("--port", port, "-P", "sd25", "param", "apply", str(other))
    assert r.code == 2 and "profile is620p" in r.err, r.err
    for text, message in (
        ("parameters: {}\n", "'parameters'"),
        ("save: maybe\nparameters: {Po101: 40}\n", "save must be"),
        ("parameter: {Po101: 40}\n", "unknown key"),
        ("parameters: {Po101: true}\n", "is not a value"),
        ("parameters: {So-00: 40}\n", "not a settable parameter"),
    ):
        other.write_text(text)
        r = cli("--port", port, "-P", "sd25", "param", "apply", str(other))
        assert r.code == 2 and message in r.err, (text, r.err)
    assert stored(port) == before


def test_a_snapshot_is_a_desired_set(cli, tmp_path):
    sim = ("--port", "sim", "-P", "sd25")
    snap = tmp_path / "snap.yaml"
    assert cli(*sim, "param", "backup", "--snapshot", "-o", str(snap)).code == 0
    assert cli(*sim, "param", "set", "Po101=50", "Po500=3").code == 0  # Po500 is axis-specific: left out
    r = cli(*sim, "param", "apply", str(snap), "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert [s["code"] for s in data["settings"] if s["changed"]] == ["Po101"]
    assert "Po500" in {s["code"] for s in data["skipped"]} and data["verified"] is True
    assert cli(*sim, "param", "apply", str(snap), "--check").code == 0


def test_the_library_returns_facts_and_check_mode_writes_nothing(sim_dir):
    wanted = desired.from_mapping({"parameters": {"Pn101": 30.0, "Pn100": "45"}}, "task")
    with open_drives(resolve(ConnectOptions(port="sim", profile="dsx7e")), notice=lambda _m: None) as (d,):
        checked = apply.apply(d, wanted, check=True)
        assert checked.status == apply.WOULD_CHANGE and [s.entry.code for s in checked.changes] == ["Pn100", "Pn101"]
        assert apply.apply(d, wanted, check=True).status == apply.WOULD_CHANGE  # the first wrote nothing
        done = apply.apply(d, wanted)
        assert done.status == apply.CHANGED and done.persisted and done.verified
        assert [(s.before, s.after) for s in done.settings] == [(320, 450), (180, 300)]
        assert done.diff_text() == ("Pn100: 32.0 1/s\nPn101: 18.0 Hz\n", "Pn100: 45.0 1/s\nPn101: 30.0 Hz\n")
        again = apply.apply(d, wanted)
        assert again.status == apply.UNCHANGED and again.verified and again.changes == []
        assert json.loads(json.dumps(again.as_json()))["changed"] is False
    with pytest.raises(UsageError, match="profile sd25"):
        desired.from_mapping({"profile": "sd25", "parameters": {"Pn101": 1}}, "task").check_profile(d.profile)
