"""`servotool alarm`: unknown codes are shown as unknown, only the current alarm is active, each alarm comes with the
manual's causes (or says the manual gives none), and the history is the drive's own log, read as its manual
documents it: DSX7E's records beside the current fault, SD25's So-10..12, SDC's PN58, IS620P's selected records."""

from __future__ import annotations

import pytest

from servotool.drive import Drive
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.loader import load_profile
from servotool.ops import alarms
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim
from tests.frames import plain_read


def test_a_code_the_profile_does_not_list_is_shown_as_unknown():
    for pid in ("sd25", "dsx7e", "is620p", "sdc"):
        state = alarms.describe(load_profile(pid), 0x1234)
        assert state.display == "0x1234" and state.known is False and state.active
        assert state.name == f"unknown alarm (not in the {pid} profile)"
        assert state.clearable is None and state.manual is not None and not state.manual.causes
    assert alarms.describe(load_profile("dsx7e"), 0x25).name.startswith("Communication with master lost")


def test_causes_and_remedies_come_from_the_manual_with_their_lines_or_say_there_are_none():
    e09 = alarms.describe(load_profile("dsx7e"), 0x09).manual
    assert e09 is not None and e09.source == "L4250-4269" and "Un002 and Un027" in e09.causes[0].remedy
    assert alarms.describe(load_profile("dsx7e"), 0x0A).manual.source == "L4250-4269"  # the manual groups E09/E0A
    none = alarms.describe(load_profile("dsx7e"), 0x1C).manual  # E1C: listed in 7.1, no row in 7.3
    assert none is not None and not none.causes and none.note == "section 7.3 gives no cause or remedy for this fault"
    is620p = alarms.describe(load_profile("is620p"), 0x500).manual  # Er.500: the drive's own fault, not this volume's
    assert not is620p.causes and "general IS620P manual" in is620p.note
    assert alarms.describe(load_profile("is620p"), 0xD07).manual.causes[0].remedy.startswith("check the CANopen")
    assert alarms.describe(load_profile("sdc"), 4).manual.source == "L1648, L1679-1683"
    assert alarms.describe(load_profile("sd25"), 18).manual.causes[0].remedy == "raise Po013 by hand as appropriate"


def _history(sim_dir, codes: list[int]) -> None:
    """Put these codes in the simulated DSX7E's alarm history (most recent first), with no alarm active."""
    sim_drive = build_drive(load_profile("dsx7e"), 1)
    with sim_drive.session():
        sim_drive.firmware.alarm_history[:] = codes
        sim_drive.bank.save()


def test_history_marks_past_alarms_inactive_and_unknown_codes_honestly(cli, sim_dir):
    _history(sim_dir, [0x09, 0x1234])
    r = cli("--port", "sim", "alarm", "history", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["current"]["active"] is False and data["slots"] == 3 and data["kept_in"] == "Un106..Un118"
    items = data["records"]
    assert [(i["record"], i["display"]) for i in items] == [(1, "E09"), (2, "0x1234")]  # no empty records
    assert not any(i["active"] for i in items)  # no alarm now: nothing in the history is active
    assert items[1]["known"] is False and "not in the dsx7e profile" in items[1]["name"]
    assert items[0]["manual"]["source"] == "L4250-4269"
    assert items[0]["recorded"]["speed"] == {"code": "Un107", "value": 0, "unit": "rpm"}
    r = cli("--port", "sim", "alarm", "history")
    assert "unknown alarm (not in the dsx7e profile)" in r.out and "(now)" not in r.out
    assert "watch Un002 and Un027" in r.out  # E09's causes, once


def test_an_empty_history_is_one_line_not_a_table_of_empty_records(cli):
    for pid, kept in (
        ("dsx7e", "3 past alarms (Un106..Un118)"),
        ("sd25", "3 past alarms (So-10..So-12)"),
        ("sdc", "1 past alarm (PN58)"),
    ):
        r = cli("--port", "sim", "-P", pid, "alarm", "history")
        assert r.code == 0, r.err
        assert r.out.splitlines() == ["no alarm now", f"no past alarm: the drive keeps {kept}, all empty"], r.out


def _serve(pid: str):
    profile = load_profile(pid)
    sim_drive = build_drive(profile, 1)
    sim = EmbeddedSim([sim_drive])
    link = RtuMaster(LinkSettings(port=sim.port, timeout=0.5, retries=0))
    return profile, sim_drive, sim, link


def test_history_marks_only_the_current_alarm_active(sim_dir):
    profile, sim_drive, sim, link = _serve("dsx7e")
    try:
        sim_drive.firmware.alarm_history[:] = [0x09]
        sim_drive.firmware.trip("overload")  # E09 again: now current, and the log keeps the one before it
        h = alarms.history(Drive(link, profile, 1))
    finally:
        link.close()
        sim.close()
    assert h.current.display == "E09" and h.current.active and h.excludes_current
    assert [(r.number, r.alarm.display, r.alarm.active) for r in h.records] == [(1, "E09", False)]
    assert [r.meaning for r in h.current_recorded] == ["time", "speed", "bus_voltage", "current"]
    assert h.current_recorded[2].reading.eng == 311


@pytest.mark.parametrize(("pid", "history_code"), [("sd25", "So-10"), ("sdc", "PN58")])
def test_where_the_log_holds_the_current_alarm_its_newest_record_is_marked_now(sim_dir, pid, history_code):
    profile, sim_drive, sim, link = _serve(pid)
    try:
        sim_drive.firmware.trip("following_error" if pid == "sdc" else "overload")
        d = Drive(link, profile, 1)
        h = alarms.history(d)
        code = h.current.code
        assert d.read(history_code)[0].raw == code  # the drive's own register holds it
        assert plain_read(sim.port, profile.entry(history_code).address, 1) == [code]
    finally:
        link.close()
        sim.close()
    assert h.current.active and not h.excludes_current
    assert [(r.number, r.alarm.code, r.alarm.active) for r in h.records] == [(1, code, True)]


def test_is620p_records_are_read_one_at_a_time_through_h0b_33_and_the_selector_is_put_back(sim_dir):
    profile, sim_drive, sim, link = _serve("is620p")
    try:
        for kind in ("overspeed", "overload"):
            sim_drive.firmware.trip(kind)
            sim_drive.firmware.reset_alarm()
        sim_drive.firmware.trip("following_error")  # current: Er.b00; before it Er.610, then Er.500
        d = Drive(link, profile, 1)
        h = alarms.history(d)
        assert d.read("H0B-33")[0].raw == 0  # put back as it was
        d.write_verified(profile.entry("H0B-33"), 2)  # a panel user left a past record selected
        with pytest.raises(alarms.VerifyError, match="H0B-33 = 2 selects past alarm record 2"):
            alarms.current(d)
    finally:
        link.close()
        sim.close()
    assert h.current.display == "Er.b00" and h.slots == 9 and h.kept_in == "H0B-33 = 1..9"
    assert [r.alarm.display for r in h.records] == ["Er.610", "Er.500"]
    assert {r.meaning for r in h.records[0].recorded} >= {"time", "speed", "bus_voltage", "inputs", "outputs"}
    outputs = next(r for r in h.current_recorded if r.meaning == "outputs")
    assert "DO4" in outputs.text  # DO4 is assigned ALM (11) at the factory: on at the fault


def test_alarm_show_gives_the_causes_and_remedies_fitted_to_80_columns(cli, sim_dir):
    sim_drive = build_drive(load_profile("dsx7e"), 1)
    with sim_drive.session():
        sim_drive.firmware.trip("overspeed")
        sim_drive.bank.save()
    r = cli("--port", "sim", "alarm", env={"COLUMNS": "80"})
    assert r.code == 0, r.err
    lines = r.out.splitlines()
    assert lines[0] == "ALARM E17: Overspeed (clearable)"
    assert "causes and remedies (manual L4309-4332):" in lines[1]
    assert "-> look at the speed waveform and lower the regulator gains" in r.out
    assert all(len(line) <= 80 for line in lines), r.out
    data = cli("--port", "sim", "alarm", "--json").json()
    assert data["manual"]["source"] == "L4309-4332" and len(data["manual"]["causes"]) == 4
