"""Entries the drive lacks (exception 02) and writes it refuses: found by splitting coalesced reads, named once,
remembered, and reported by backup, list, diff and restore, which complete."""

from __future__ import annotations

import pytest
import yaml

from servotool.clock import VirtualClock
from servotool.drive import Drive, NotOnDrive
from servotool.model.loader import load_profile
from servotool.ops import backup
from servotool.sim.device import SimulatedDrive
from servotool.sim.virtual import VirtualLink

LACKING = ["Pn101", "Pn512"]  # one in the middle of a coalesced block, one near the end of another


def virtual_drive(missing: list[str]) -> tuple[Drive, VirtualLink]:
    profile = load_profile("dsx7e")
    sim = SimulatedDrive(profile, 1, persist=False)
    sim.set_missing(missing)
    link = VirtualLink([sim], VirtualClock())
    return Drive(link, profile, 1), link


def test_split_reads_find_each_missing_entry_and_remember_it(sim_dir):
    d, link = virtual_drive(LACKING)
    full, _ = virtual_drive([])
    taken = backup.take(d)
    assert taken.missing == LACKING
    expected = backup.take(full).values
    assert taken.values == {c: v for c, v in expected.items() if c not in LACKING}
    assert backup.take(d).values == taken.values
    with pytest.raises(NotOnDrive, match="Pn101: not on this drive"):
        d.read("Pn100", "Pn101")
    before = link.requests
    with pytest.raises(NotOnDrive):
        d.read("Pn101")
    assert link.requests == before  # remembered: no request at all


def test_once_found_a_hole_costs_no_splitting_again(sim_dir):
    d, link = virtual_drive(LACKING)
    full, full_link = virtual_drive([])
    backup.take(d)
    start = link.requests
    backup.take(d)  # known holes: never asked for, never coalesced across
    backup.take(full)
    assert link.requests - start <= full_link.requests + 2 * len(LACKING)


def lack(profile: str, codes: list[str]) -> None:
    SimulatedDrive(load_profile(profile), 1).set_missing(codes)


def test_backup_list_and_diff_complete_and_name_the_missing_entries_once(cli, tmp_path):
    lack("dsx7e", LACKING)
    f = tmp_path / "b.yaml"
    r = cli("--port", "sim", "param", "backup", "-o", str(f), "--json")
    assert r.code == 0, r.err
    assert r.json()["missing"] == LACKING
    for code in LACKING:
        assert r.err.count(f"{code} (") == 1 and "not on this drive" in r.err
    doc = yaml.safe_load(f.read_text())
    assert doc["missing"] == {c: "not on this drive" for c in LACKING}
    assert not set(LACKING) & set(doc["values"])
    r = cli("--port", "sim", "param", "list", "--json")
    assert r.code == 0, r.err
    rows = {x["code"]: x for x in r.json()}
    assert rows["Pn101"]["missing"] and rows["Pn101"]["value"] is None and rows["Pn100"]["value"] == 32.0
    r = cli("--port", "sim", "param", "list")
    assert r.code == 0 and r.err.count("Pn512 (") == 1 and "Pn100" in r.out
    r = cli("--port", "sim", "param", "diff", str(f), "--json")
    assert r.code == 0, r.err
    assert r.json()["missing"] == LACKING and r.json()["differences"] == []
    r = cli("--port", "sim", "param", "get", "Pn101")
    assert r.code == 1 and "Pn101: not on this drive" in r.err


def test_restore_across_missing_and_refused_entries_writes_the_rest(cli, tmp_path):
    f = tmp_path / "full.yaml"
    assert cli("--port", "sim", "param", "set", "Pn100=45.0", "Pn101=30.0", "Pn102=25.0", "Pn417=5").code == 0
    assert cli("--port", "sim", "param", "backup", "-o", str(f)).code == 0  # complete: taken before
    assert cli("--port", "sim", "param", "reset", "--yes").code == 0
    lack("dsx7e", ["Pn101"])
    SimulatedDrive(load_profile("dsx7e"), 1).inject_fault("Pn417", 2)  # refuses writes there
    r = cli("--port", "sim", "param", "restore", str(f), "--yes", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["missing"] == ["Pn101"]
    assert [x["code"] for x in data["refused"]] == ["Pn417"] and "exception 02" in data["refused"][0]["why"]
    assert {"Pn100", "Pn102"} <= set(data["written"]) and "Pn417" not in data["written"]
    assert r.err.count("Pn101 (") == 1
    r = cli("--port", "sim", "param", "get", "Pn100", "Pn102", "Pn417", "--json")
    assert [x["value"] for x in r.json()] == [45.0, 25.0, load_profile("dsx7e").entry("Pn417").default]
    r = cli("--port", "sim", "param", "restore", str(f), "--yes")
    assert r.code == 0 and "Pn417 (" in r.err and "not restored: the drive refuses writes there" in r.err
