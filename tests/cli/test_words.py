"""Plain words: what the user can do, fix commands with the user's connection options, details behind -v."""

from __future__ import annotations

import json

from servotool.cli import render
from servotool.cli.messages import error_text, plain
from servotool.connection import ConnectOptions
from servotool.errors import MissingRole, ServoError


def test_manual_line_references_only_with_verbose():
    text = "needs H0C-09 = 1 (communication VDI, L3392) and H17-00 (is620p.md L1044); 2 stop bits (L2713-2719)"
    assert plain(text) == "needs H0C-09 = 1 (communication VDI) and H17-00; 2 stop bits"
    assert plain(text, verbose=True) == text


def test_commands_a_library_message_suggests_get_the_users_connection_options():
    given = ConnectOptions(port="COM3", profile="sd25")
    text = error_text(ServoError("the drive is in alarm (see 'servotool alarm', clear it first)"), given)
    assert "'servotool --port COM3 --profile sd25 alarm'" in text
    already = "set it with 'servotool --port sim param set Pn4=1'"
    assert error_text(ServoError(already), given) == already
    serve = "start 'servotool sim serve --port tcp://127.0.0.1:0' and give its tcp:// port"
    assert error_text(ServoError(serve), given) == serve


def test_a_missing_role_is_worded_as_what_the_user_can_do():
    exc = MissingRole("alarm clear", "alarm_reset", "sd25")
    text = error_text(exc, ConnectOptions())
    assert "role" not in text and "alarm reset" in text and "panel" in text
    assert "role 'alarm_reset'" in error_text(exc, ConnectOptions(), verbose=True)
    for role, words in (
        ("alarm_history_1", "the alarm history of"),
        ("inertia_id", "the inertia identification function of"),
    ):
        assert words in error_text(MissingRole("x", role, "sdc"), ConnectOptions())


def test_unknown_code_suggests_and_the_fix_command_keeps_the_connection_options(cli):
    r = cli("--port", "sim", "-P", "is620p", "param", "get", "H08-0O")
    assert r.code == 2
    assert "did you mean H08-00" in r.err
    assert "'servotool --port sim --profile is620p param find H08-0O'" in r.err


def test_other_spellings_units_and_enum_names_end_to_end(cli):
    r = cli("--port", "sim", "-P", "is620p", "param", "set", "H08.00=30Hz", "--json")
    assert r.code == 0, r.err
    assert r.json()["changed"][0] == {
        "code": "H08-00",
        "old": 25.0,
        "new": 30.0,
        "unit": "Hz",
        "effect": "unknown",
        "value_unverified": "raw scale inferred from the decimals printed in the range",
    }
    r = cli("--port", "sim", "param", "set", "Pn027=3000Hz")
    assert r.code == 2 and "is in rpm" in r.err
    r = cli("--port", "sim", "-P", "sdc", "param", "set", "PN4=jog")
    assert r.code == 0 and "(jog)" in r.out
    r = cli("--port", "sim", "-P", "sdc", "param", "get", "PN4", "--json")
    assert r.json()[0]["meaning"] == "jog"


def test_groups_case_insensitive_and_did_you_mean(cli):
    r = cli("--port", "sim", "param", "list", "--group", "GAIN", "--class", "pn", "--json")
    assert r.code == 0 and "Pn101" in {row["code"] for row in r.json()}
    r = cli("--port", "sim", "param", "list", "--group", "gian")
    assert r.code == 2 and "did you mean gain" in r.err
    r = cli("profiles", "show", "dsx7")
    assert r.code == 2 and "did you mean dsx7e" in r.err


def test_cautions_are_one_line_each_unless_explained(capsys):
    lines = [
        "H06-02 (speed_reference): used as the speed reference: this volume documents no route (L3217)",
        "this drive has no communication timeout: if this program dies the motor keeps running",
    ]
    render.caution(lines)
    short = capsys.readouterr().err.splitlines()
    assert short == [
        "servotool: caution: H06-02 (speed reference) is not confirmed by the manual",
        "servotool: caution: this drive has no communication timeout",
        "servotool: (--explain shows why)",
    ]
    render.Verbosity.explain = True
    try:
        render.caution(lines)
    finally:
        render.Verbosity.explain = False
    assert "keeps running" in capsys.readouterr().err


def test_a_dead_man_caution_is_one_line_without_manual_lines(capsys):
    render.caution(
        [
            "the dead-man (segment) relies on IS620P CANopen manual L3426-3438 (H11 segment parameters), "
            "L3164-3166; is620p.md L477-491; unverified: how a segment is started is the general manual's"
        ]
    )
    assert (
        capsys.readouterr().err.splitlines()[0]
        == "servotool: caution: the dead-man (segment) is not confirmed by the manual"
    )


def test_warnings_leave_manual_lines_to_verbose(capsys, monkeypatch):
    text = "not saved to EEPROM (store them with Sn-SEt; its mechanism is not printed, L417-419, L844-874)"
    render.warn(text)
    assert (
        capsys.readouterr().err.strip()
        == "servotool: warning: not saved to EEPROM (store them with Sn-SEt; its mechanism is not printed)"
    )
    monkeypatch.setattr(render.Verbosity, "level", 1)
    render.warn(text)
    assert "L417-419, L844-874" in capsys.readouterr().err


def test_a_whole_digit_entry_carries_its_fields_meanings_in_json(cli):
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po001", "--json")
    assert r.code == 0, r.err
    row = r.json()[0]
    assert row["fields"] == {"Y": 1, "X": 21}
    assert row["meanings"] == {"Y": "CCW seen from the shaft", "X": "bus"}


def test_a_fields_meaning_is_accepted_by_name(cli):
    r = cli("--port", "sim", "-P", "sd25", "param", "set", "--save", "Po001.X=internal speed")
    assert r.code == 0, r.err
    assert r.out.splitlines() == [
        "Po001 (Control mode and forward direction): d 1 21 -> d 1 0 [takes effect after a power cycle]",
        "1 value stored in EEPROM",
    ]
    r = cli("--port", "sim", "-P", "sd25", "param", "set", "--save", "Po001.X=bsu")
    assert r.code == 2 and "none of 0=internal speed" in r.err and "did you mean bus" in r.err


def test_what_a_killed_restore_left_is_told_with_quiet_and_the_users_options(cli, sim_dir, tmp_path):
    from servotool.files import backup_dir
    from servotool.model.loader import load_profile
    from servotool.ops.journal import journal_dir, record_path
    from servotool.session import sim_bus

    class Drive:  # what names a drive's record: its bus, profile and unit
        port, unit, profile = sim_bus("dsx7e"), 1, load_profile("dsx7e")

    auto = tmp_path / "auto.yaml"
    assert cli("--port", "sim", "param", "backup", "-o", str(auto)).code == 0
    assert cli("--port", "sim", "param", "set", "Pn101=25").code == 0  # the dead restore's one write
    assert journal_dir() == backup_dir() / "journal"
    journal_dir().mkdir(parents=True, exist_ok=True)
    record = record_path(Drive())  # type: ignore[arg-type]
    record.write_text(
        json.dumps({"op": {"name": "restore", "auto_backup": str(auto), "targets": {"Pn101": 250}}, "pid": 1})
    )
    r = cli("-q", "--port", "sim", "param", "get", "Pn004")
    assert r.code == 0, r.err
    assert "a restore (pid 1) was interrupted after writing 1 of 1 entry" in r.err
    assert f"'servotool --port sim param restore {auto}'" in r.err
    assert not record.exists()
