"""Backup, diff, restore and factory reset: library tests on an in-process simulated drive, plus real CLI runs."""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from servotool.cli.messages import error_text
from servotool.connection import ConnectOptions, resolve
from servotool.drive import Drive
from servotool.errors import DeviceError, ModbusException, UsageError
from servotool.model.loader import load_profile
from servotool.ops import backup, params, restore
from servotool.session import open_drives
from servotool.sim.device import SimulatedDrive

CHANGES = {
    "Pn003": "20",
    "Pn004": "600",
    "Pn025": "250.0",
    "Pn026": "260.0",
    "Pn027": "5000",
    "Pn036": "90",
    "Pn043": "400",
    "Pn044": "30",
    "Pn047": "150",
    "Pn100": "45.0",
    "Pn101": "30.0",
    "Pn102": "25.0",
    "Pn106": "50.0",
    "Pn120": "-5.0",
    "Pn128": "1.00",
    "Pn417": "5",
    "Pn512": "300",
    "Pn513": "150",
    "Pn514": "80",
    "Pn008": "20000",
}
WRITE_FRAME = re.compile(r">> 01 (06|10) ")


@pytest.fixture
def auto_dir(sim_dir, tmp_path, monkeypatch) -> Path:
    """Automatic backups of this test go here, never to the user's data dir."""
    d = tmp_path / "auto"
    monkeypatch.setenv("SERVOTOOL_BACKUP_DIR", str(d))
    return d


@contextmanager
def sim() -> Iterator[Drive]:
    with open_drives(resolve(ConnectOptions(port="sim", profile="dsx7e")), notice=lambda _m: None) as (d,):
        yield d


def count_writes(d: Drive) -> list[int]:
    """Count every write request the drive receives from now on."""
    sent: list[int] = []
    real = d.link.write

    def counting(*args, **kwargs):
        sent.append(1)
        return real(*args, **kwargs)

    d.link.write = counting  # type: ignore[method-assign]
    return sent


def changed_drive_backup(path: Path) -> dict[str, int]:
    """Set CHANGES on the simulated drive, back it up to path; return the values written."""
    with sim() as d:
        params.apply_set(d, params.prepare_set(d, [f"{k}={v}" for k, v in CHANGES.items()]))
        backup.write_backup(d, path)
        return backup.take(d).values


def test_round_trip_restores_every_value_and_a_second_restore_writes_nothing(auto_dir, tmp_path):
    f = tmp_path / "drive.yaml"
    wanted = changed_drive_backup(f)
    with sim() as d:
        auto = restore.factory_reset(d)
        assert restore.not_at_default(d) == []
        assert backup.load(auto, d.profile).values == wanted  # the automatic backup holds the pre-reset state
        b = backup.load(f, d.profile)
        current = backup.take(d).values
        plan = restore.restore_changes(d.profile, b, current)
        assert {e.code for e, _, _ in plan.changes} == set(CHANGES)
        effects = [e.effect for e, _, _ in plan.changes]
        assert effects == sorted(effects, key=restore.EFFECT_ORDER.__getitem__)  # power-cycle entries last
        notes: list[str] = []
        report = restore.restore(d, b, plan, notice=notes.append)
        assert notes == [f"automatic backup of the drive's current state: {report.auto_backup}"]
        assert report.auto_backup.parent == auto_dir
        assert backup.take(d).values == wanted
        writes = count_writes(d)
        assert restore.restore_file(d, f) == "nothing to restore: the drive already matches"
        assert writes == []


def test_fault_midway_rolls_back_to_the_automatic_backup(auto_dir, tmp_path, cli):
    f = tmp_path / "target.yaml"
    changed_drive_backup(f)
    with sim() as d:
        restore.factory_reset(d)
        before = backup.take(d).values
        order = [e.code for e, _, _ in restore.restore_changes(d.profile, backup.load(f, d.profile), before).changes]
    victim = order[len(order) // 2]  # half of the plan is written before the refusal
    SimulatedDrive(load_profile("dsx7e"), 1).inject_fault(victim)
    r = cli("--port", "sim", "param", "restore", str(f), "--yes")
    assert r.code == 1, r.err
    where = r.err.index("automatic backup of the drive's current state:")
    assert where < r.err.index(f"restore stopped at {victim}")
    assert f"rolled back {len(order) // 2} written entries; read back, the drive equals the automatic" in r.err
    (auto,) = auto_dir.glob("*before-restore.yaml")
    with sim() as d:
        assert backup.take(d).values == backup.load(auto, d.profile).values == before


def test_a_value_that_does_not_read_back_is_rolled_back_too(auto_dir, tmp_path):
    f = tmp_path / "target.yaml"
    changed_drive_backup(f)
    with sim() as d:
        restore.factory_reset(d)
        before = backup.take(d).values
        plan = restore.restore_changes(d.profile, backup.load(f, d.profile), before)
        victim = plan.changes[3][0]
        real = d.write_raw
        misbehave = [1]

        def off_by_one(entry, raw):  # the drive stores something else than asked
            wrong = entry is victim and bool(misbehave)
            real(entry, raw + 1 if wrong else raw)
            if wrong:
                misbehave.pop()

        d.write_raw = off_by_one  # type: ignore[method-assign]
        with pytest.raises(restore.RestoreFailed, match=f"restore stopped at {victim.code}: .*reads back") as exc:
            restore.restore(d, backup.load(f, d.profile), plan)
        assert exc.value.exit_code == 3
        assert "rolled back 3 written entries; read back, the drive equals the automatic backup" in str(exc.value)
        assert backup.take(d).values == before

        misbehave[:] = [1] * 10  # now it keeps storing the wrong value: say so, exactly
        with pytest.raises(restore.RestoreFailed) as exc:
            restore.restore(d, backup.load(f, d.profile), plan)
        now = d.read_one(victim.code)
        assert now.raw == before[victim.code] + 1
        assert f"rollback incomplete (could not undo {victim.code} ({victim.code}: wrote" in str(exc.value)
        assert f"1 entry differs from the automatic backup {auto_dir}" in str(exc.value)
        assert f"{victim.code} is {now.text}, was " in str(exc.value)
        assert exc.value.next_step == "restore"  # the CLI words it with the user's connection options
        auto = exc.value.auto_backup
        assert error_text(exc.value, ConnectOptions(port="sim", unit=1)).endswith(
            f"; run 'servotool --port sim --unit 1 param restore {auto}' once the cause is fixed"
        )


def test_restore_stores_in_eeprom_on_a_switchable_drive_and_puts_the_switch_back(auto_dir, tmp_path):
    f = tmp_path / "sd25.yaml"
    opts = resolve(ConnectOptions(port="sim", profile="sd25"))
    with open_drives(opts, notice=lambda _m: None) as (d,):
        switch = d.read_one("Po505").raw  # factory: writes stay in RAM
        params.apply_set(d, params.prepare_set(d, ["Po301=50"]))
        backup.write_backup(d, f)
        restore.factory_reset(d)
        b = backup.load(f, d.profile)
        report = restore.restore(d, b, restore.restore_changes(d.profile, b, backup.take(d).values))
        assert [e.code for e in report.written] == ["Po301"] and report.persisted
        assert d.read_one("Po505").raw == switch
    drive = SimulatedDrive(load_profile("sd25"), 1)
    assert drive.bank.eeprom["Po301"] == 50  # survives a power cycle
    drive.power_cycle()
    assert drive.bank.value("Po301") == 50


def test_the_eeprom_switch_in_a_backup_never_redirects_the_restore(auto_dir, tmp_path):
    f = tmp_path / "is620p.yaml"
    with open_drives(resolve(ConnectOptions(port="sim", profile="is620p")), notice=lambda _m: None) as (d,):
        params.apply_set(d, params.prepare_set(d, ["H08-00=30.0", "H08-02=50.0"]))
        d.write_raw(d.profile.entry("H0C-13"), 0)  # this axis kept Modbus writes in RAM when backed up
        backup.write_backup(d, f)
        restore.factory_reset(d)  # H0C-13 back to 1 (store in EEPROM)
        b = backup.load(f, d.profile)
        plan = restore.restore_changes(d.profile, b, backup.take(d).values)
        assert [e.code for e, _ in plan.skipped] == ["H0C-13"]
        report = restore.restore(d, b, plan)
        assert sorted(e.code for e in report.written) == ["H08-00", "H08-02"] and report.persisted
        assert d.read_one("H0C-13").raw == 1
    drive = SimulatedDrive(load_profile("is620p"), 1)
    drive.power_cycle()
    assert [drive.bank.value(c) for c in ("H08-00", "H08-02")] == [300, 500]


def test_rollback_on_a_switchable_drive_is_judged_without_the_switch_it_flipped(auto_dir, tmp_path, cli):
    f = tmp_path / "sd25.yaml"
    changes = ["Po301=50", "Po109=5", "Po110=30", "Po111=40"]
    assert cli("--port", "sim", "-P", "sd25", "param", "set", *changes).code == 0
    assert cli("--port", "sim", "-P", "sd25", "param", "backup", "-o", str(f)).code == 0
    assert cli("--port", "sim", "-P", "sd25", "param", "reset", "--yes").code == 0
    SimulatedDrive(load_profile("sd25"), 1).inject_fault("Po110")
    r = cli("--port", "sim", "-P", "sd25", "param", "restore", str(f), "--yes")
    assert r.code == 1 and "restore stopped at Po110" in r.err
    assert "read back, the drive equals the automatic backup" in r.err, r.err


def _edits() -> list[tuple[str, object, str]]:
    return [
        ("truncated", lambda t: t[: len(t) // 2], "line \\d+: invalid YAML|incomplete"),
        ("cut mid-values", lambda t: t[: t.index("Pn512:")], "incomplete"),
        ("broken yaml", lambda t: "[1, 2", "line \\d+: invalid YAML"),
        ("not UTF-8", lambda t: t.encode().replace(b"model: DSX7E", b"model: DSX\xe9"), r"not UTF-8 text \(byte \d+\)"),
        ("empty", lambda t: "", "not a servotool backup"),
        ("wrong type", lambda t: t.replace("Pn004: 250", "Pn004: fast"), "Pn004: value 'fast' is not an integer"),
        ("float", lambda t: t.replace("Pn004: 250", "Pn004: 250.5"), "is not an integer"),
        ("bool", lambda t: t.replace("Pn004: 250", "Pn004: true"), "is not an integer"),
        ("unit type", lambda t: t.replace("unit: 1", "unit: one"), "'unit' is missing or of the wrong type"),
        (
            "unknown code",
            lambda t: t.replace("Pn004: 250", "Pn004: 250\n  Pn999: 1").replace("display:", "display:\n  Pn999: x"),
            "unknown parameter Pn999",
        ),
        (
            "monitor code",
            lambda t: t.replace("Pn004: 250", "Pn004: 250\n  Un000: 1").replace("display:", "display:\n  Un000: x"),
            "unknown parameter Un000",
        ),
        ("out of range", lambda t: t.replace("Pn004: 250", "Pn004: 99"), "outside 100..12000"),
        ("other model", lambda t: t.replace("model: DSX7E", "model: OTHER"), "not of this DSX7E"),
        ("other profile", lambda t: t.replace("profile: dsx7e", "profile: sd25"), "not of this DSX7E"),
        ("bad checksum", lambda t: t.replace("Pn004: 250", "Pn004: 260"), "checksum mismatch"),
    ]


@pytest.fixture(scope="module")
def good_backup_text(tmp_path_factory) -> str:
    mp = pytest.MonkeyPatch()
    mp.setenv("SERVOTOOL_SIM_DIR", str(tmp_path_factory.mktemp("sim")))
    try:
        path = tmp_path_factory.mktemp("b") / "good.yaml"
        with sim() as d:
            backup.write_backup(d, path)
        return path.read_text()
    finally:
        mp.undo()


@pytest.mark.parametrize(("case", "edit", "message"), _edits(), ids=[c for c, _, _ in _edits()])
def test_every_bad_file_is_refused_with_one_clear_line(good_backup_text, tmp_path, case, edit, message):
    f = tmp_path / "bad.yaml"
    edited = edit(good_backup_text)
    f.write_bytes(edited if isinstance(edited, bytes) else edited.encode())
    with pytest.raises(UsageError) as exc:
        backup.load(f, load_profile("dsx7e"))
    text = str(exc.value)
    assert re.search(message, text), text
    assert "\n" not in text and text.startswith(str(f))


def test_force_accepts_an_edited_checksum_with_a_warning_but_never_a_bad_value(good_backup_text, tmp_path):
    f = tmp_path / "edited.yaml"
    f.write_text(good_backup_text.replace("Pn004: 250", "Pn004: 260"))
    b = backup.load(f, load_profile("dsx7e"), force=True)
    assert b.values["Pn004"] == 260 and "checksum mismatch" in b.warnings[0]
    f.write_text(good_backup_text.replace("Pn004: 250", "Pn004: 99"))
    with pytest.raises(UsageError, match="outside"):
        backup.load(f, load_profile("dsx7e"), force=True)


def test_cli_refuses_bad_files_before_connecting_or_writing(auto_dir, tmp_path, cli, good_backup_text):
    edited = tmp_path / "edited.yaml"
    edited.write_text(good_backup_text.replace("Pn100: 320", "Pn100: 330"))
    truncated = tmp_path / "truncated.yaml"
    truncated.write_text(good_backup_text[: len(good_backup_text) // 3])
    for f, why in ((edited, "checksum mismatch"), (truncated, "incomplete|invalid YAML")):
        r = cli("--port", "sim", "-v", "param", "restore", str(f), "--yes")
        assert r.code == 2 and re.search(why, r.err), r.err
        assert not WRITE_FRAME.search(r.err) and not auto_dir.exists()
    r = cli("--port", "sim", "param", "restore", str(edited), "--yes", "--force")
    assert r.code == 0, r.err
    assert "warning:" in r.err and "checksum mismatch" in r.err and "1 parameter restored" in r.out
    with sim() as d:
        assert d.read_one("Pn100").raw == 330


def test_backups_are_atomic_and_never_overwrite(auto_dir, tmp_path):
    f = tmp_path / "a.yaml"
    f.write_text("precious\n")
    with sim() as d:
        with pytest.raises(UsageError, match=r"exists; .* --force"):
            backup.write_backup(d, f)
        assert f.read_text() == "precious\n"
        assert not list(tmp_path.glob(".*.tmp"))
        backup.write_backup(d, f, force=True)
        assert yaml.safe_load(f.read_text())["model"] == "DSX7E"
        a1, a2 = backup.auto_backup(d, "x"), backup.auto_backup(d, "x")
    assert a1 != a2 and a1.exists() and a2.exists()
    assert not list(tmp_path.rglob("*.tmp"))


def test_backup_file_has_the_metadata_and_a_checksum_of_the_values(auto_dir, tmp_path):
    f = tmp_path / "b.yaml"
    with sim() as d:
        backup.write_backup(d, f)
    data = yaml.safe_load(f.read_text())
    assert data["profile"] == "dsx7e" and data["profile_version"] == "1.1" and data["model"] == "DSX7E"
    assert data["unit"] == 1 and data["tool_version"] and data["created"].endswith("+00:00")
    assert list(data["identity"]) == ["Un200", "Un201", "Un202", "Un203", "Un204", "Un205"]  # the identity checks
    assert len(data["values"]) == 108 and data["display"]["Pn100"] == "32.0 1/s"
    assert re.fullmatch(r"[0-9a-f]{64}", data["checksum"])


def test_a_backup_records_identity_from_the_profiles_identity_section(auto_dir, tmp_path):
    """One home for identity: IS620P's model entry H01-02 is in its identity section (no role names it)."""
    f = tmp_path / "b.yaml"
    with open_drives(resolve(ConnectOptions(port="sim", profile="is620p")), notice=lambda _m: None) as (d,):
        backup.write_backup(d, f)
        profile = d.profile
    data = yaml.safe_load(f.read_text())
    assert list(data["identity"]) == ["H01-00", "H01-01", "H01-02"]
    # A file written before (identity by the old roles) still loads, its identity as written.
    data["identity"] = {"H01-00": "101.0"}
    f.write_text(yaml.safe_dump(data, sort_keys=False))
    assert backup.load(f, profile).identity == {"H01-00": "101.0"}


def test_axis_specific_entries_groups_and_include(auto_dir, tmp_path):
    f = tmp_path / "b.yaml"
    with sim() as d:
        params.apply_set(d, params.prepare_set(d, ["Pn610=5", "Pn100=45"]))
        backup.write_backup(d, f)
        restore.factory_reset(d)
        b, current = backup.load(f, d.profile), backup.take(d).values
        plan = restore.restore_changes(d.profile, b, current)
        assert [e.code for e, _, _ in plan.changes] == ["Pn100"] and plan.skipped[0][0].code == "Pn610"
        plan = restore.restore_changes(d.profile, b, current, include=["Pn610"])
        assert {e.code for e, _, _ in plan.changes} == {"Pn100", "Pn610"}
        assert restore.restore_changes(d.profile, b, current, only="io").changes == []
        assert [e.code for e, _, _ in restore.restore_changes(d.profile, b, current, only="gain").changes] == ["Pn100"]
        with pytest.raises(UsageError, match="unknown group"):
            restore.restore_changes(d.profile, b, current, only="nope")


def test_servo_on_blocks_changes_that_need_the_servo_off(auto_dir):
    with sim() as d:
        d.trigger("servo_on", "test", 1)
        with pytest.raises(UsageError, match="switch the servo off first"):
            restore.check_servo_off(d, [d.profile.entry("Pn100")], "the restore")
        d.trigger("servo_on", "test", 0)
        restore.check_servo_off(d, [d.profile.entry("Pn100")], "the restore")


def test_cli_backup_reset_diff_and_restore(auto_dir, tmp_path, cli):
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    with sim() as d:
        backup.write_backup(d, a)
        params.apply_set(d, params.prepare_set(d, ["Pn100=45", "Pn008=20000"]))
    r = cli("--port", "sim", "param", "backup", "-o", str(b))
    assert r.code == 0 and f"saved to {b}" in r.out, r.err
    r = cli("--port", "sim", "param", "backup", "-o", str(b))
    assert r.code == 2 and "exists" in r.err
    r = cli("param", "diff", str(a), str(b), "--json")
    assert r.code == 1, r.err  # they differ (issue 35: 0 equal, 1 differ)
    rows = {x["code"]: x for x in r.json()["differences"]}
    assert set(rows) == {"Pn100", "Pn008"} and rows["Pn008"]["effect"] == "power_cycle"
    assert rows["Pn100"]["a"] == 32.0 and rows["Pn100"]["b"] == 45.0
    r = cli("param", "diff", str(b), "--changed-from-default", "--json")
    assert {x["code"] for x in r.json()["differences"]} == {"Pn100", "Pn008"}
    r = cli("param", "diff", str(a), str(b), "--changed-from-default")
    assert r.code == 2 and "not both" in r.err
    edited = tmp_path / "edited.yaml"
    edited.write_text(b.read_text().replace("Pn100: 450", "Pn100: 460"))
    r = cli("param", "diff", str(a), str(edited), "--json")  # a diff writes nothing: compared anyway
    assert r.code == 1 and "checksum mismatch" in r.err and "warning" in r.err
    assert {x["code"]: x["b"] for x in r.json()["differences"]}["Pn100"] == 46.0
    r = cli("--port", "sim", "param", "reset")  # no --yes and stdin is not a terminal
    assert r.code == 2 and "pass --yes" in r.err
    r = cli("--port", "sim", "param", "reset", "--yes")
    assert r.code == 0 and "automatic backup of the drive's current state:" in r.err, r.err
    assert "power-cycle the drive for the defaults of: Pn008" in r.out
    r = cli("--port", "sim", "param", "diff", str(b))
    assert r.code == 1 and re.search(r"Pn100 .* 32\.0 .* 45\.0 .* 1/s", r.out), r.out
    assert re.search(r"Pn008 .* power cycle", r.out), r.out
    r = cli("--port", "sim", "param", "restore", str(b))
    assert r.code == 2 and "pass --yes" in r.err
    r = cli("--port", "sim", "param", "restore", str(b), "--dry-run", "--json")
    assert [x["code"] for x in r.json()["changes"]] == ["Pn100", "Pn008"] and r.json()["written"] == []
    r = cli("--port", "sim", "-q", "param", "restore", str(b), "--yes")
    assert r.code == 0 and "2 parameters restored" in r.out, r.err
    assert "automatic backup of the drive's current state:" in r.err  # even with --quiet
    assert "power-cycle the drive for: Pn008" in r.out
    r = cli("--port", "sim", "-v", "param", "restore", str(b), "--yes", "--json")
    assert r.code == 0 and r.json()["written"] == [] and not WRITE_FRAME.search(r.err)


def test_backup_checks_its_output_before_any_drive_io(cli, tmp_path):
    """Issue 14 defect 7: no port is opened (here: one that does not exist) before the output is known good."""
    taken = tmp_path / "taken.yaml"
    taken.write_text("precious\n")
    taken.chmod(0o644)
    nowhere = ("--port", str(tmp_path / "no-such-port"), "-P", "sd25")
    r = cli(*nowhere, "param", "backup", "-o", str(taken))
    assert r.code == 2 and "exists; choose another name or pass --force" in r.err, r.err
    r = cli(*nowhere, "param", "backup", "-o", str(tmp_path / "no" / "dir.yaml"))
    assert r.code == 2 and "no folder" in r.err
    r = cli(*nowhere, "param", "backup", "-o", "--help")
    assert r.code == 2 and "looks like an option" in r.err
    assert not (Path(__file__).resolve().parents[2] / "--help").exists()
    assert cli("--port", "sim", "param", "backup", "-o", str(taken), "--force").code == 0
    assert taken.stat().st_mode & 0o777 == 0o644  # replaced, mode kept


def eeprom_and_ram(profile: str, code: str) -> tuple[int, int]:
    """(RAM, EEPROM) of one entry, from the simulated drive's own state file (no servotool reads)."""
    drive = SimulatedDrive(load_profile(profile), 1)
    return drive.bank.ram[code], drive.bank.eeprom[code]


@pytest.mark.parametrize(
    ("profile", "code", "stored", "in_ram", "raw"),
    [("sd25", "Po003", "20", "16", 16), ("is620p", "H08-00", "30.0", "25.0", 250)],
)
def test_restore_stores_a_value_ram_holds_but_eeprom_does_not(
    cli, auto_dir, tmp_path, profile, code, stored, in_ram, raw
):
    """Issue 30 item 5: after set --save CODE=a and set --no-save CODE=b, restore of a backup holding b said
    "nothing to restore: the drive already matches", and a power cycle brought a back."""
    f = tmp_path / "b.yaml"
    p = ("--port", "sim", "-P", profile)
    assert cli(*p, "param", "set", "--save", f"{code}={stored}").code == 0
    assert cli(*p, "param", "set", "--no-save", f"{code}={in_ram}").code == 0
    assert cli(*p, "param", "backup", "-o", str(f)).code == 0
    assert eeprom_and_ram(profile, code) == (raw, int(float(stored) * (10 if "." in stored else 1)))
    r = cli(*p, "param", "diff", str(f), "--json")
    assert r.code == 0 and r.json()["compared"] == "RAM" and r.json()["differences"] == []
    r = cli(*p, "param", "diff", str(f))
    assert "compared with the drive's RAM: what EEPROM holds" in r.err and "drive RAM" in r.out, r.err
    r = cli(*p, "param", "restore", str(f), "--yes", "--ram-only")
    assert r.code == 0 and "nothing to restore: the drive's RAM already matches (--ram-only" in r.out, r.out
    assert eeprom_and_ram(profile, code)[1] != raw  # --ram-only left EEPROM as it was
    r = cli(*p, "param", "restore", str(f), "--yes", "--json")
    assert r.code == 0, r.err
    assert r.json()["written"] == [] and code in r.json()["stored_again"] and r.json()["persisted"] is True
    assert eeprom_and_ram(profile, code) == (raw, raw)
    assert cli("sim", "reset", "-P", profile, "--power-cycle").code == 0
    assert eeprom_and_ram(profile, code) == (raw, raw)


def test_a_drive_that_stores_every_write_is_compared_and_restored_as_read(cli, auto_dir, tmp_path):
    """DSX7E stores every write: RAM is the stored copy, so a restore writes only what differs and says so."""
    f = tmp_path / "b.yaml"
    assert cli("--port", "sim", "param", "backup", "-o", str(f)).code == 0
    r = cli("--port", "sim", "param", "diff", str(f), "--json")
    assert r.json()["compared"] == "RAM (= EEPROM: the drive stores every write)"
    r = cli("--port", "sim", "-v", "param", "restore", str(f), "--yes")
    assert r.code == 0 and "nothing to restore: the drive already matches" in r.out and not WRITE_FRAME.search(r.err)


def test_values_written_again_in_blocks_skip_an_address_the_drive_refuses(auto_dir, tmp_path):
    """The values RAM holds go in FC16 blocks; a block the drive refuses at one address is split, the refused
    entry reported, and the rest stored."""
    opts = resolve(ConnectOptions(port="sim", profile="sd25"))
    with open_drives(opts, notice=lambda _m: None) as (d,):
        b = backup.take(d)
        plan = restore.restore_changes(d.profile, b, b.values)
        assert plan.changes == [] and len(plan.again) > 100
        victim = plan.again[len(plan.again) // 2][0]
        SimulatedDrive(load_profile("sd25"), 1).inject_fault(victim.code, exception=2)
        writes = count_writes(d)
        report = restore.restore(d, b, plan)
    assert [e.code for e, _ in report.refused] == [victim.code]
    assert {e.code for e in report.stored_again} == {e.code for e, _ in plan.again} - {victim.code}
    assert len(writes) < len(plan.again) / 3  # blocks, not one request a value


class Flaky:
    """A Link over a virtual SD25 whose write of one value is refused (exception 03, so the restore rolls back)
    and which then times out on `reads_lost` of the reads that follow (a burst of faults on the line)."""

    def __init__(self, refuse: tuple[int, int], reads_lost: set[int], writes_lost: set[int] = frozenset()) -> None:
        from servotool.clock import VirtualClock
        from servotool.sim.firmware import build_drive
        from servotool.sim.virtual import VirtualLink

        self.profile = load_profile("sd25")
        clock = VirtualClock()
        self.sim = build_drive(self.profile, 1, clock, persist=False)
        self.link = VirtualLink([self.sim], clock)
        self.refuse, self.reads_lost, self.writes_lost = refuse, reads_lost, writes_lost
        self.after = None  # reads (and writes) counted from the refusal on
        self.armed = False

    def read(self, unit, address, count, **kw):
        if self.after is not None:
            self.after["reads"] += 1
            if self.after["reads"] in self.reads_lost:
                raise DeviceError(f"read {count} register(s) at {address}: no response within 1 s")
        return self.link.read(unit, address, count, **kw)

    def write(self, unit, address, values, **kw):
        if self.armed and (address, values) == (self.refuse[0], [self.refuse[1]]):
            self.after = {"reads": 0, "writes": 0}
            raise ModbusException(3, f"write 1 register(s) at {address}")
        if self.after is not None:
            self.after["writes"] += 1
            if self.after["writes"] in self.writes_lost:
                raise DeviceError(f"write 1 register(s) at {address}: no response within 1 s")
        self.link.write(unit, address, values, **kw)

    def close(self):
        pass


def _failing_restore(link: Flaky) -> tuple[restore.RestoreFailed, Drive]:
    d = Drive(link, link.profile, 1, port="virtual-line")
    params.set_values(d, params.prepare_set(d, ["Po003=20", "Po101=30", "Po110=40"]), True)
    b = backup.take(d)
    params.set_values(d, params.prepare_set(d, ["Po003=16", "Po101=60", "Po110=200"]), True)
    link.armed = True
    with pytest.raises(restore.RestoreFailed) as caught:
        restore.restore(d, b, restore.restore_changes(d.profile, b, params.read_settings(d)))
    return caught.value, d


def test_a_rolled_back_restore_says_so_though_a_later_read_meets_a_fault(sim_dir):
    """Issue 30 item 7: after a rollback the drive had answered (15 of 15 cases), one final read met a fault and the
    account said "the drive no longer answers, so its state is unknown". The rollback's own read-backs are the
    account; a fault after them changes nothing."""
    link = Flaky(refuse=(110, 40), reads_lost=set(range(7, 40)))  # every read after the rollback's is lost
    exc, _d = _failing_restore(link)
    assert "the drive no longer answers" not in str(exc)
    assert "rolled back 2 written entries; read back, the drive equals the automatic backup" in str(exc), exc
    assert exc.equals_backup is True and sorted(exc.rolled_back) == ["Po003", "Po101"]
    assert {c: link.sim.bank.ram[c] for c in ("Po003", "Po101", "Po110")} == {"Po003": 16, "Po101": 600, "Po110": 200}


def test_an_entry_the_rollback_could_not_undo_nor_read_is_named_unknown_beside_what_was_rolled_back(sim_dir):
    """The rollback goes newest first: Po101 is written back and verified, then the line loses Po003's write back
    and every read after it: Po003's state is UNKNOWN, and the account still says that Po101 was rolled back."""
    link = Flaky(refuse=(110, 40), reads_lost=set(range(5, 100)), writes_lost={2, 3, 4})
    exc, _d = _failing_restore(link)
    text = str(exc)
    assert "Po003 could not be undone nor read back, so its state is UNKNOWN" in text, text
    assert "rolled back Po101 (verified by read-back)" in text, text
    assert exc.equals_backup is None and exc.next_step == "compare"
