"""Many buses from one host (issue 35 item 3): `fleet backup|drift|apply INVENTORY` against several `sim serve`
machines, a failure on one drive or bus leaving the others done; stored values judged with pymodbus' own client."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest
import yaml

from servotool.errors import UsageError
from servotool.fleet import inventory
from tests import machines
from tests.ops.plain_client import read_registers

GOLDEN = {"servotool_settings": 1, "save": True, "parameters": {"Po101": 40.0, "Po102": 25.0, "Po110": 150}}
ADDRESSES = {"Po101": 101, "Po102": 102, "Po110": 110}
FACTORY = {"Po101": 600, "Po102": 500, "Po110": 200}
WANTED = {"Po101": 400, "Po102": 250, "Po110": 150}


def stored(port: str, unit: int) -> dict[str, int]:
    return {code: read_registers(port, address, unit=unit)[0] for code, address in ADDRESSES.items()}


def write(path: Path, data: object) -> Path:
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture
def fleet(sim_dir, tmp_path):
    started = [machines.start(f"m{i}", tmp_path / "machines", "sd25", [1, 2]) for i in (1, 2, 3)]
    yield started
    machines.stop(started)


def dead_port() -> str:
    """A loopback port where nothing listens: bound and never listening, held until the next call (closed, the
    port could go to another test's `sim serve` meanwhile)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    dead_port.keep = s  # type: ignore[attr-defined]
    return f"tcp://127.0.0.1:{s.getsockname()[1]}"


def test_backup_drift_and_apply_run_every_bus_and_a_failure_leaves_the_others_done(fleet, cli, tmp_path):
    write(tmp_path / "golden.yaml", GOLDEN)
    buses = [{"machine": m.name, "port": m.port, "units": [1, 2]} for m in fleet]
    body = {"servotool_fleet": 1, "defaults": {"profile": "sd25", "golden": "golden.yaml"}, "buses": buses}
    inv = write(tmp_path / "inv.yaml", body)
    dead = {"machine": "m4", "port": dead_port(), "units": [1], "timeout": 0.2, "retries": 0}
    with_dead = write(tmp_path / "dead.yaml", {**body, "buses": [*buses, dead]})

    r = cli("fleet", "backup", str(inv), "-o", str(tmp_path / "snaps"), "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["summary"] == {"saved": 6} and len(data["buses"]) == 3
    first = tmp_path / "snaps" / "m1" / f"{fleet[0].port[6:].replace(':', '_')}-unit2-sd25.yaml"
    assert first.is_file() and yaml.safe_load(first.read_text())["machine"] == "m1"
    r = cli("fleet", "backup", str(inv), "-o", str(tmp_path / "snaps"), "--json")
    assert r.json()["summary"] == {"unchanged": 6}  # the same snapshot: the file is left as it was

    r = cli("fleet", "drift", str(inv), "--json")
    assert r.code == 1 and r.json()["summary"] == {"differs": 6}, r.err
    r = cli("fleet", "apply", str(inv), "--check", "--json")
    assert r.code == 1 and r.json()["summary"] == {"would change": 6}, r.err
    assert all(stored(m.port, u) == FACTORY for m in fleet for u in (1, 2))  # --check wrote nothing

    fleet[2].inject_fault("sd25", 2, "Po110")  # m3 unit 2 refuses its last write: rolled back
    r = cli("fleet", "apply", str(with_dead), "--json")
    assert r.code == 5, r.err  # some failed, the others were done
    rows = {(d["machine"], d["unit"]): d for d in r.json()["drives"]}
    assert r.json()["summary"] == {"changed": 5, "failed": 2}
    assert rows[("m3", 2)]["status"] == "failed" and rows[("m3", 2)]["as_before"] is True
    assert rows[("m3", 2)]["exit_status"] == 1 and "apply stopped at Po110" in rows[("m3", 2)]["error"]
    assert "connection refused" in rows[("m4", 1)]["error"]
    for m in fleet:
        for u in (1, 2):
            assert stored(m.port, u) == (FACTORY if (m.name, u) == ("m3", 2) else WANTED), (m.name, u)

    r = cli("fleet", "drift", str(inv), "--json")
    assert r.code == 1 and r.json()["summary"] == {"differs": 1, "equal": 5}, r.err
    r = cli("fleet", "drift", str(inv), "--against", str(tmp_path / "snaps"), "--json")
    assert r.code == 1 and r.json()["summary"] == {"differs": 5, "equal": 1}  # the snapshots hold the old values
    r = cli("fleet", "apply", str(inv))
    assert r.code == 5 and "FAILED" in r.out and "5 unchanged" in r.out, r.out
    r = cli("log", "--machine", "m1", "--json")
    assert sorted({(x["unit"], x["code"]) for x in r.json()}) == [(u, c) for u in (1, 2) for c in ADDRESSES]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.pop("servotool_fleet"), "not a servotool fleet inventory"),
        (lambda d: d.update(buses=[]), "one bus at least"),
        (lambda d: d["buses"][0].pop("machine"), "'machine'"),
        (lambda d: d["buses"][0].update(machine="press 01"), "'machine'"),
        (lambda d: d["buses"][0].update(units=[]), "'units'"),
        (lambda d: d["buses"][0].update(units=[1, 1]), "listed twice"),
        (lambda d: d["buses"][0].update(units=[300]), "bad unit id 300"),
        (lambda d: d["buses"][0].update(baud="fast"), "baud must be a whole number"),
        (lambda d: d["buses"][0].update(colour="red"), "unknown key(s) colour"),
        (lambda d: d["buses"].append({**d["buses"][0], "machine": "other", "units": [3]}), "listed twice"),
        (lambda d: d["buses"][1].update(port="tcp://localhost:5020"), "listed twice"),  # one bus, two spellings
        (lambda d: d["buses"][0].update(port="tcp://nowhere"), "expected tcp://HOST:PORT"),
    ],
)
def test_an_inventory_is_checked_before_any_port_opens(tmp_path, change, message):
    data = {
        "servotool_fleet": 1,
        "buses": [
            {"machine": "press-01", "port": "tcp://127.0.0.1:5020", "units": [1, 2]},
            {"machine": "press-02", "port": "tcp://127.0.0.1:5021", "units": [1]},
        ],
    }
    change(data)
    with pytest.raises(UsageError, match=message.replace("(", r"\(").replace(")", r"\)")):
        inventory.load(write(tmp_path / "inv.yaml", data))


def test_golden_paths_are_relative_to_the_inventory_and_units_may_have_their_own(tmp_path):
    data = {
        "servotool_fleet": 1,
        "defaults": {"golden": "g/all.yaml", "profile": "sd25"},
        "buses": [
            {"machine": "p1", "port": "/dev/ttyUSB0", "baud": 19200, "units": [1, {"unit": 2, "golden": "x.yaml"}]}
        ],
    }
    found = inventory.load(write(tmp_path / "inv.yaml", data))
    (bus,) = found.buses
    assert [(t.unit, t.golden) for t in bus.targets] == [(1, tmp_path / "g/all.yaml"), (2, tmp_path / "x.yaml")]
    assert bus.name == "ttyUSB0" and bus.options.baud == 19200 and bus.options.profile == "sd25"


def test_a_missing_golden_file_is_refused_before_any_bus_is_opened(cli, tmp_path):
    data = {"servotool_fleet": 1, "buses": [{"machine": "p1", "port": dead_port(), "units": [1], "golden": "no.yaml"}]}
    r = cli("fleet", "apply", str(write(tmp_path / "inv.yaml", data)))
    assert r.code == 2 and "no.yaml does not exist" in r.err, r.err
