"""All four profiles: valid, usable on the simulated drive, and honest about what is unverified."""

from __future__ import annotations

import pytest

from servotool.profile import builtin_ids, load_profile

PROFILES = ["dsx7e", "sd25", "is620p", "sdc"]


def test_all_four_ship():
    assert set(PROFILES) <= set(builtin_ids())


@pytest.mark.parametrize("pid", PROFILES)
def test_param_list_on_the_simulated_drive(cli, pid):
    r = cli("--port", "sim", "--profile", pid, "param", "list", "--json")
    assert r.code == 0, r.err
    rows = r.json()
    assert len(rows) == len([e for e in load_profile(pid).of_class("Pn") if e.readable])
    assert all(not row["changed"] for row in rows)            # a fresh simulated drive holds factory defaults
    r = cli("profiles", "show", pid, "--unverified", "--json")
    listed = r.json()["entries"]
    assert listed and all(e["unverified"] for e in listed)


@pytest.mark.parametrize("pid", PROFILES)
def test_key_roles_point_at_the_right_class(pid):
    p = load_profile(pid)
    for role, cls in (("speed_feedback", "Un"), ("torque_feedback", "Un"), ("jog_speed", "Pn"),
                      ("comm_address", "Pn")):
        entry = p.role(role)
        assert entry is not None and entry.cls == cls, (pid, role)
    for e in p.entries:
        assert e.source, e.code


def test_display_encoded_sd25_values_read_and_write_in_the_manuals_form(cli):
    r = cli("--port", "sim", "--profile", "sd25", "param", "get", "Po001", "Po505")
    assert "d 1 21" in r.out and "d 1 1" in r.out
    r = cli("--port", "sim", "--profile", "sd25", "param", "set", "Po001=X=20", "--json")
    assert r.code == 0, r.err
    assert r.json()["changed"][0]["new"] == "d 1 20"
    assert cli("--port", "sim", "--profile", "sd25", "param", "set", "Po001=X=100").code == 2


def test_is620p_signed_and_32_bit_entries_follow_the_printed_ranges_and_types():
    p = load_profile("is620p")
    assert (p.entry("H12-20").type, p.entry("H12-20").min, p.entry("H12-20").max) == ("s16", -9000, 9000)
    assert p.entry("H12-47").min <= p.entry("H12-47").default == -100        # printed default now fits
    assert (p.entry("H11-12").type, p.entry("H11-12").min) == ("s32", -1073741824)
    assert p.entry("H0B-58").words == 2 and p.entry("H05-46").type == "s32"   # 'int32' printed in lower case
    assert p.entry("H05-17").unverified                                       # 35~327567 cannot be 16-bit


def test_the_readme_table_states_each_profiles_real_counts():
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "profiles" / "README.md").read_text()
    for pid in PROFILES:
        p = load_profile(pid)
        row = re.search(rf"^\| {pid} \| [^|]+ \| (\d+) / (\d+) / (\d+) / (\d+) \| (\d+) \| (\d+) \|", text, re.M)
        assert row, pid
        counts = [len(p.of_class(c)) for c in ("Pn", "Un", "Sn", "Fn")]
        assert [int(x) for x in row.groups()] == [*counts, sum(1 for e in p.entries if e.unverified), len(p.roles)]
