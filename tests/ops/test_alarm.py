"""`servotool alarm`: unknown codes are shown as unknown, only the current alarm is active."""

from __future__ import annotations

from servotool.drive import Drive
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.loader import load_profile
from servotool.ops import alarms
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


def test_a_code_the_profile_does_not_list_is_shown_as_unknown():
    for pid in ("sd25", "dsx7e", "is620p", "sdc"):
        state = alarms.describe(load_profile(pid), 0x1234)
        assert state.display == "0x1234" and state.known is False and state.active
        assert state.name == f"unknown alarm (not in the {pid} profile)"
        assert state.clearable is None
    assert alarms.describe(load_profile("dsx7e"), 0x25).name.startswith("Communication with master lost")


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
    items = r.json()
    assert [i["display"] for i in items[:2]] == ["E09", "0x1234"]
    assert not any(i["active"] for i in items)  # no alarm now: nothing in the history is active
    assert items[1]["known"] is False and "not in the dsx7e profile" in items[1]["name"]
    r = cli("--port", "sim", "alarm", "history")
    assert "unknown alarm (not in the dsx7e profile)" in r.out and "active" not in r.out


def test_history_marks_only_the_current_alarm_active(sim_dir):
    profile = load_profile("dsx7e")
    sim_drive = build_drive(profile, 1)
    sim = EmbeddedSim([sim_drive])
    try:
        sim_drive.firmware.alarm_history[:] = [0x09]
        sim_drive.firmware.trip("overload")  # E09 again: now current and the newest entry
        link = RtuMaster(LinkSettings(port=sim.port, timeout=0.5, retries=0))
        items = alarms.history(Drive(link, profile, 1))
        link.close()
    finally:
        sim.close()
    assert [(i.display, i.active) for i in items[:2]] == [("E09", True), ("E09", False)]
