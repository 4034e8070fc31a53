"""The Ansible collection (ansible/collections/.../servotool/drives, issue 35 item 2) run by ansible-core itself:
one playbook against three machines, each a `sim serve` drive on its own loopback port (inventory hosts on the
local connection). Check mode writes nothing (read by a plain Modbus client inside the play), a second apply
changes nothing, drift finds none, backups land on the control node named by machine, identity and time, and a
machine whose drive refuses a write fails alone, rolled back, while the others are done."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from tests import machines
from tests.frames import plain_read

pytest.importorskip("ansible.release", reason="ansible-core is not installed (pip install -e '.[test]' brings it)")

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
GOLDEN = {"Po101": 40.0, "Po102": 25.0, "Po110": 150}
ADDRESSES = {"Po101": 101, "Po102": 102, "Po110": 110}
FACTORY = {"101": 600, "102": 500, "110": 200}
WANTED = {"101": 400, "102": 250, "110": 150}
HOSTS = ("m1", "m2", "m3")
REFUSING = "m3"  # its drive refuses the write of Po110 (exception 03), after Po101 and Po102 were written


def stored(port: str) -> dict[str, int]:
    return {str(a): plain_read(port, a, 1, unit=1)[0] for a in ADDRESSES.values()}


@pytest.fixture
def fleet(sim_dir, tmp_path):
    started = [machines.start(name, tmp_path / "machines", "sd25", [1]) for name in HOSTS]
    yield {m.name: m for m in started}
    machines.stop(started)


def playbook(tmp_path: Path, fleet: dict[str, machines.Machine]) -> subprocess.CompletedProcess[str]:
    """ansible-playbook on an inventory of the machines, the collection from this checkout; one run."""
    results, backups = tmp_path / "results", tmp_path / "backups"
    results.mkdir()
    inventory = {
        "all": {
            "children": {
                "machines": {
                    "hosts": {name: {"drive_port": m.port} for name, m in fleet.items()},
                    "vars": {
                        "ansible_connection": "local",
                        "ansible_python_interpreter": sys.executable,
                        "golden_gains": GOLDEN,
                        "addresses": " ".join(map(str, ADDRESSES.values())),
                        "reader": str(HERE / "read_registers.py"),
                        "backups": str(backups),
                        "results": str(results),
                    },
                }
            }
        }
    }
    (tmp_path / "inventory.yml").write_text(yaml.safe_dump(inventory))
    command = [sys.executable, "-m", "ansible", "playbook", "-i", str(tmp_path / "inventory.yml")]
    return subprocess.run(
        [*command, str(HERE / "playbook.yml")],
        capture_output=True,
        text=True,
        env=ansible_env(tmp_path, forks=len(fleet)),
        cwd=tmp_path,
        timeout=300,
    )


def ansible_env(tmp_path: Path, forks: int = 5) -> dict[str, str]:
    """ansible-core's settings for a test: its own home and temp folders, the collection from this checkout."""
    home = tmp_path / "ansible-home"
    return {
        **os.environ,
        "ANSIBLE_CONFIG": str(tmp_path / "no-ansible.cfg"),  # no ansible.cfg of the cwd or the user's
        "ANSIBLE_HOME": str(home),
        "ANSIBLE_LOCAL_TEMP": str(home / "tmp"),
        "ANSIBLE_REMOTE_TEMP": str(home / "remote"),
        "ANSIBLE_COLLECTIONS_PATH": str(ROOT / "ansible" / "collections"),
        "ANSIBLE_FORKS": str(forks),
        "ANSIBLE_NOCOLOR": "1",
        "ANSIBLE_RETRY_FILES_ENABLED": "0",
        "ANSIBLE_DEPRECATION_WARNINGS": "0",
        "LC_ALL": "C.UTF-8",  # ansible-core refuses a non-UTF-8 locale
        "LANG": "C.UTF-8",
    }


def test_a_playbook_applies_idempotently_checks_without_writing_and_a_refusing_machine_fails_alone(
    fleet, tmp_path, cli
):
    fleet[REFUSING].inject_fault("sd25", 1, "Po110")
    assert all(stored(m.port) == FACTORY for m in fleet.values())

    run = playbook(tmp_path, fleet)

    out = run.stdout + run.stderr
    assert run.returncode == 2, out  # a host failed; the play went on for the others
    recap = {line.split()[0]: line for line in run.stdout.splitlines() if " : ok=" in line}
    assert set(recap) == set(HOSTS), out
    assert all("failed=0" in recap[h] for h in HOSTS if h != REFUSING) and "failed=1" in recap[REFUSING], recap
    found = {h: json.loads((tmp_path / "results" / f"{h}.json").read_text()) for h in HOSTS}

    for host, r in found.items():
        facts = r["facts"]["1"]
        assert facts["profile"] == "sd25" and facts["machine"] == host and facts["firmware"], facts
        assert facts["alarm"]["active"] is False and facts["servo_on"] is False
        checked = r["checked"]  # check mode: would change, shown as a diff, and nothing written
        assert checked["changed"] and checked["status"] == "would change", checked
        assert "Po101: 60.0 Hz" in checked["diff"]["before"] and "Po101: 40.0 Hz" in checked["diff"]["after"]
        assert r["after_check"] == FACTORY, host

    for host in HOSTS:
        if host == REFUSING:
            continue
        r = found[host]
        assert r["applied"]["changed"] and r["applied"]["verified"] and r["applied"]["persisted"], r["applied"]
        assert r["again"]["changed"] is False and r["again"]["status"] == "unchanged"  # idempotent
        assert r["drift"]["changed"] is False and r["drift"]["differences"] == []
        assert r["backup"]["changed"] and r["backup_again"]["changed"] is False  # equal: not written again
        path = Path(r["backup"]["dest"])
        assert path.parent == tmp_path / "backups" / host and path == Path(r["backup_again"]["dest"])
        assert path.name.startswith("sd25-unit1-") and path.name.endswith("Z.yaml"), path.name  # identity, time
        assert "Po101" in path.read_text() and [p.name for p in path.parent.iterdir()] == [path.name]
        assert stored(fleet[host].port) == WANTED, host

    failed = found[REFUSING]["applied"]  # rolled back: Po101 and Po102 written, then put back
    assert failed["failed"] and failed["as_before"] is True and failed["exit_status"] == 1, failed
    assert sorted(failed["rolled_back"]) == ["Po101", "Po102"] and "apply stopped at Po110" in failed["msg"]
    assert found[REFUSING]["again"] is None and not (tmp_path / "backups" / REFUSING).exists()
    assert stored(fleet[REFUSING].port) == FACTORY

    logged = cli("log", "--machine", "m1", "--json").json()  # the drive's change log names the playbook's task
    assert sorted(x["code"] for x in logged) == sorted(GOLDEN)
    assert {(x["who"], x["source"]) for x in logged} == {("test-runner", "ansible servotool.drives.settings")}


def test_the_documented_example_and_every_module_s_documentation_parse(tmp_path):
    """What a user reads first: ansible-doc shows each module (its DOCUMENTATION, EXAMPLES and RETURN are YAML),
    the example playbook and inventory pass ansible's syntax check, and its golden gains are entries of the profile
    its inventory names."""
    from servotool.model.loader import load_profile
    from servotool.ops import desired

    env = ansible_env(tmp_path)
    modules = [f"servotool.drives.{name}" for name in ("settings", "facts", "backup", "drift")]
    shown = subprocess.run(
        [sys.executable, "-m", "ansible", "doc", "--json", *modules], capture_output=True, text=True, env=env
    )
    assert shown.returncode == 0, shown.stderr
    docs = json.loads(shown.stdout)
    assert sorted(docs) == sorted(modules) and all(d["doc"] and d["examples"] and d["return"] for d in docs.values())
    assert "port" in docs["servotool.drives.settings"]["doc"]["options"]

    docs_dir = ROOT / "ansible" / "collections" / "ansible_collections" / "servotool" / "drives" / "docs"
    checked = subprocess.run(
        [
            sys.executable,
            "-m",
            "ansible",
            "playbook",
            "--syntax-check",
            "-i",
            str(docs_dir / "inventory.yml"),
            str(docs_dir / "golden-gains.yml"),
        ],
        capture_output=True,
        text=True,
        env=env,
    )
    assert checked.returncode == 0, checked.stdout + checked.stderr
    group = yaml.safe_load((docs_dir / "inventory.yml").read_text())["all"]["children"]["press_x"]["vars"]
    golden = yaml.safe_load((docs_dir / "group_vars" / "press_x.yml").read_text())["golden_gains"]
    wanted = desired.from_mapping({"parameters": golden, "save": True}, "press_x golden_gains")
    desired.check(wanted, load_profile(group["servo_profile"]))  # UsageError on a code the profile lacks
