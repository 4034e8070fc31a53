"""All four profiles: valid, usable on the simulated drive, and honest about what is unverified."""

from __future__ import annotations

from pathlib import Path

import pytest

from servotool.model.loader import builtin_ids, load_profile

PROFILES = ["dsx7e", "sd25", "is620p", "sdc"]


def test_all_four_ship_and_pass_profiles_check_by_default_or_by_id(cli):
    assert set(PROFILES) <= set(builtin_ids())
    r = cli("profiles", "check", "--json")  # no argument: every built-in profile
    assert r.code == 0, r.err
    assert {Path(row["file"]).stem for row in r.json()} == set(builtin_ids())
    r = cli("profiles", "check", "sd25", "no-such-profile.yaml")
    assert r.code == 2 and "sd25.yaml: ok" in r.out and "no-such-profile.yaml: cannot read" in r.out


@pytest.mark.parametrize("pid", PROFILES)
def test_param_list_on_the_simulated_drive(cli, pid):
    r = cli("--port", "sim", "--profile", pid, "param", "list", "--json")
    assert r.code == 0, r.err
    rows = r.json()
    assert len(rows) == len([e for e in load_profile(pid).of_class("Pn") if e.readable])
    assert all(not row["changed"] for row in rows)  # a fresh simulated drive holds factory defaults
    r = cli("profiles", "show", pid, "--unverified", "--json")
    listed = r.json()["entries"]
    assert listed and all(e["unverified"] for e in listed)


@pytest.mark.parametrize("pid", PROFILES)
def test_key_roles_point_at_the_right_class(pid):
    p = load_profile(pid)
    for role, cls in (("speed_feedback", "Un"), ("torque_feedback", "Un"), ("jog_speed", "Pn"), ("comm_address", "Pn")):
        entry = p.role(role)
        assert entry is not None and entry.cls == cls, (pid, role)
    for e in p.entries:
        assert e.source, e.code


def test_display_encoded_sd25_values_read_and_write_in_the_manuals_form(cli):
    r = cli("--port", "sim", "--profile", "sd25", "param", "get", "Po001", "Po505")
    assert "d 1 21" in r.out and "d 1 1" in r.out
    r = cli("--port", "sim", "--profile", "sd25", "param", "set", "--save", "Po001=X=20", "--json")
    assert r.code == 0, r.err
    assert r.json()["changed"][0]["new"] == 0x0114 and r.json()["changed"][0]["new_text"] == "d 1 20"
    assert cli("--port", "sim", "--profile", "sd25", "param", "set", "Po001=X=100").code == 2


def test_is620p_signed_and_32_bit_entries_follow_the_printed_ranges_and_types():
    p = load_profile("is620p")
    assert (p.entry("H12-20").type, p.entry("H12-20").min, p.entry("H12-20").max) == ("s16", -9000, 9000)
    assert p.entry("H12-47").min <= p.entry("H12-47").default == -100  # printed default now fits
    assert (p.entry("H11-12").type, p.entry("H11-12").min) == ("s32", -1073741824)
    assert p.entry("H0B-58").words == 2 and p.entry("H05-46").type == "s32"  # 'int32' printed in lower case
    assert p.entry("H05-17").unverified  # 35~327567 cannot be 16-bit


def test_the_readme_table_states_each_profiles_real_counts():
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "profiles" / "README.md").read_text()
    for pid in PROFILES:
        p = load_profile(pid)
        row = re.search(rf"^\| {pid} \| [^|]+ \| (\d+) / (\d+) / (\d+) / (\d+) \| (\d+) \| (\d+) \|", text, re.M)
        assert row, pid
        counts = [len(p.of_class(c)) for c in ("Pn", "Un", "Sn", "Fn")]
        assert [int(x) for x in row.groups()] == [*counts, sum(1 for e in p.entries if e.unverified), len(p.roles)]


def test_sd25_alarms_are_the_manuals_list_and_the_simulator_reports_them_by_kind(sim_dir):
    from servotool.drive import Drive
    from servotool.link.master import RtuMaster
    from servotool.link.ports import LinkSettings
    from servotool.ops import alarms
    from servotool.sim.firmware import build_drive
    from servotool.sim.server import EmbeddedSim

    p = load_profile("sd25")
    shown = {a.display for a in p.alarms}
    assert len(p.alarms) == 41 and {"AL-01", "AL-31", "AL-35", "AL-59"} <= shown  # section 10.2, L8066-8113
    assert not {"AL-15", "AL-21", "AL-32", "AL-33", "AL-34"} & shown  # printed as '——'
    kinds = {k: p.alarm_of_kind(k).display for k in ("overspeed", "overload", "following_error", "inertia_id_failed")}
    assert kinds == {
        "overspeed": "AL-07",
        "overload": "AL-06",
        "following_error": "AL-09",
        "inertia_id_failed": "AL-18",
    }
    sim_drive = build_drive(p, 1)
    sim = EmbeddedSim([sim_drive])
    try:
        sim_drive.firmware.trip("overspeed")
        link = RtuMaster(LinkSettings(port=sim.port, timeout=0.5, retries=0))
        state = alarms.current(Drive(link, p, 1))  # register 926 holds the AL number
        assert (state.code, state.display, state.name) == (7, "AL-07", "Overspeed")
        link.close()
    finally:
        sim.close()


def test_sd25_lo_monitors_outside_the_900_block_use_the_20000_plus_2n_rule():
    p = load_profile("sd25")
    for n in (18, 19, 20, 21, 22, 33, 34, 36):  # L5578-5598; rule L2790
        e = p.entry(f"Lo-{n}")
        assert (e.cls, e.address, e.words) == ("Un", 20000 + 2 * n, 2) and e.unverified


@pytest.mark.parametrize("pid", PROFILES)
def test_no_boilerplate_unverified_reasons(pid):
    for e in load_profile(pid).entries:
        assert "extraction marks this entry uncertain" not in e.unverified, (pid, e.code)


def test_is620p_chapter_conflicts_are_marked_with_both_readings():
    p = load_profile("is620p")
    for code, cited in (
        ("H0C-00", "L701"),
        ("H0C-13", "L4365"),
        ("H0C-25", "L3398"),
        ("H05-35", "L1852"),
        ("H05-61", "L4295"),
        ("H09-24", "L3306"),
        ("H0C-02", "L3388"),
        ("H0C-03", "L3389"),
        ("H0C-26", "L3399"),
    ):
        assert cited in p.entry(code).unverified, code
    assert p.entry("H0C-03").enum[0] == "8N2" and p.entry("H0C-26").enum[1] == "low_word_first"
    assert (p.entry("H05-61").words, p.entry("H05-61").max) == (1, 1)  # 6.5.2: position-window unit, L4295-4302


def test_sdc_serial_entries_claim_no_effect_the_manual_does_not_state_and_the_gaps_are_filled():
    p = load_profile("sdc")
    for code in ("PN117", "PN118", "PN119"):  # L571-573 say nothing about when
        assert p.entry(code).effect == "unknown" and p.entry(code).unverified
    assert p.entry("PN119").enum == {0: "8O1", 1: "8E1", 2: "8N2", 3: "8N1"}  # L573
    for code in ("PN1", "PN4", "PN95", "PN142"):
        assert p.entry(code).unverified, code
    assert p.entry("PN130").access == "ro" and p.entry("PN131").access == "ro"  # "modification prohibited", L583
    assert p.entry("PN41").address == 41 and p.entry("PN59").address == 59 and p.entry("PN28").address == 28
    assert p.entry("UN-29").address == 0x012C + 29
