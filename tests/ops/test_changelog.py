"""The change log (issue 35 item 5): every lasting write in history, one JSON line each, from every writer through
the one write path; a motion's temporary settings left out; stored values judged with a plain Modbus client."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from servotool.connection import ConnectOptions, resolve
from servotool.model.loader import load_profile
from servotool.ops import backup, changelog, params, restore
from servotool.session import open_drives
from servotool.sim.device import SimulatedDrive
from tests.ops.plain_client import read_registers

ROOT = Path(__file__).resolve().parents[2]


def lines(sim_dir: Path) -> list[dict]:
    found, problems = changelog.read()
    assert problems == []
    return [line.data for line in found]


def test_a_set_is_logged_with_who_when_old_new_and_the_memory_it_went_to(serve, cli, sim_dir):
    port = serve("sd25")
    env = {"SERVOTOOL_MACHINE": "press-07", "SERVOTOOL_CHANGED_BY": "alice"}
    r = cli("--port", port, "-P", "sd25", "param", "set", "Po101=40", "--save", env=env)
    assert r.code == 0, r.err
    r = cli("--port", port, "-P", "sd25", "param", "set", "Po102=25", "--no-save", env=env)
    assert r.code == 0, r.err
    assert read_registers(port, 101) == [400] and read_registers(port, 102) == [250]
    first, second = lines(sim_dir)
    assert first["machine"] == "press-07" and first["who"] == "alice" and first["unit"] == 1
    assert first["source"].endswith(f"--port {port} -P sd25 param set Po101=40 --save")
    assert first["code"] == "Po101" and first["old"] == {"value": 60.0, "unit": "Hz"}
    assert first["new"] == {"value": 40.0, "unit": "Hz"} and (first["old_raw"], first["new_raw"]) == (600, 400)
    assert first["memory"] == "EEPROM" and second["memory"] == "RAM" and second["code"] == "Po102"
    assert first["identity"] == {"So-00": 100, "So-46": 100} and first["bus"].startswith("tcp://localhost:")
    assert first["time"] < second["time"] and first["time"].endswith("Z")
    r = cli("--port", port, "-P", "sd25", "param", "set", "Po101=40", env=env)  # nothing changes: nothing logged
    assert r.code == 0 and len(lines(sim_dir)) == 2


def test_a_motions_temporary_settings_are_not_history(cli, sim_dir):
    r = cli("--port", "sim", "jog", "--speed", "300", "--time", "0.3")
    assert r.code == 0, r.err
    assert lines(sim_dir) == []
    r = cli("--port", "sim", "param", "set", "Pn512=250")  # the JOG speed as a setting of its own: history
    assert r.code == 0 and [x["code"] for x in lines(sim_dir)] == ["Pn512"]


def test_restore_its_rollback_and_a_factory_reset_are_logged(sim_dir, tmp_path):
    target = tmp_path / "target.yaml"
    options = resolve(ConnectOptions(port="sim", profile="dsx7e"))
    with open_drives(options, notice=lambda _m: None) as (d,):
        params.apply_set(d, params.prepare_set(d, ["Pn100=45", "Pn101=30"]))  # outside a batch: not logged
        backup.write_backup(d, target)
        auto = restore.factory_reset(d)
    assert [x["event"] for x in lines(sim_dir)] == ["factory_reset"]
    assert lines(sim_dir)[0]["auto_backup"] == str(auto)
    with open_drives(options, notice=lambda _m: None) as (d,):
        restore.restore_file(d, target)
    changes = [(x["code"], x["old_raw"], x["new_raw"]) for x in lines(sim_dir)[1:]]
    assert sorted(changes) == [("Pn100", 320, 450), ("Pn101", 180, 300)]
    SimulatedDrive(load_profile("dsx7e"), 1).inject_fault("Pn101")
    with open_drives(options, notice=lambda _m: None) as (d,):
        restore.factory_reset(d)
        try:
            restore.restore_file(d, target)
        except restore.RestoreFailed:
            pass
        else:
            raise AssertionError("the restore should have stopped at Pn101")
    after = [(x["event"], x.get("code"), x.get("old_raw"), x.get("new_raw")) for x in lines(sim_dir)[3:]]
    # Pn100 written, Pn101 refused, Pn100 rolled back: both writes are history
    assert after == [("factory_reset", None, None, None), ("change", "Pn100", 320, 450), ("change", "Pn100", 450, 320)]


def test_processes_appending_at_once_keep_every_line_whole(serve, sim_dir):
    port = serve("sd25", "--response-delay", "5")
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "servotool", "--port", port, "-P", "sd25", "param", "set", f"Po{code}={value}"],
            cwd=ROOT,
            env=dict(os.environ),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for code, value in (("101", 41), ("102", 26), ("103", 12), ("104", 3))
    ]
    for proc in procs:
        assert proc.wait(120) == 0, proc.stderr.read() if proc.stderr else ""
    (path,) = (sim_dir.parent / "auto-backups" / "changes").rglob("*.jsonl")
    rows = [json.loads(row) for row in path.read_text().splitlines()]
    assert sorted(r["code"] for r in rows) == ["Po101", "Po102", "Po103", "Po104"]


def test_a_log_that_cannot_be_written_refuses_before_the_drive_is_changed(serve, cli, sim_dir):
    port = serve("sd25")
    (sim_dir.parent / "auto-backups").mkdir(parents=True, exist_ok=True)
    (sim_dir.parent / "auto-backups" / "changes").write_text("not a folder")
    r = cli("--port", port, "-P", "sd25", "param", "set", "Po101=40")
    assert r.code == 2 and "cannot write the change log" in r.err and "nothing was written" in r.err, r.err
    assert read_registers(port, 101) == [600]


def test_servotool_log_reads_per_unit_and_machine_and_names_a_torn_line(cli, sim_dir):
    env = {"SERVOTOOL_MACHINE": "press-07"}
    assert cli("--port", "sim", "param", "set", "Pn101=30", env=env).code == 0
    assert cli("--port", "sim", "-u", "2", "param", "set", "Pn101=31", "Pn100=40", env=env).code == 0
    r = cli("log", "--unit", "2", "--json")
    assert r.code == 0 and [x["code"] for x in r.json()] == ["Pn101", "Pn100"], r.err
    r = cli("log", "--machine", "press-07")
    assert r.code == 0 and "3 changes" in r.out and "Pn100" in r.out and "32.0 1/s" in r.out, r.out
    assert cli("log", "--machine", "elsewhere").out.startswith("no changes logged of machine elsewhere")
    assert [x["code"] for x in cli("log", "--last", "1", "--json").json()] == ["Pn100"]
    (path,) = [p for p in (sim_dir.parent / "auto-backups" / "changes").rglob("*.jsonl") if "unit1" in p.name]
    with path.open("a") as fh:
        fh.write('{"time": "2026-')  # a line cut short by a power loss
    r = cli("log", "--unit", "1", "--json")
    assert r.code == 0 and len(r.json()) == 1 and "line 2 is not JSON" in r.err, r.err
