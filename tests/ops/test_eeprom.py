"""EEPROM rules (SD25 Po505.X, IS620P H0C-13 switches; SDC RAM-only): never a needless write, never a false "saved"."""

from __future__ import annotations

import pytest

# The IS620P segment route's setup (profiles/is620p.yaml motion_setup), as a user types it.
IS620P_SETUP = ("H02-00=1", "H05-00=2", "H05-02=10000", "H11-00=0", "H0C-09=1", "H17-00=1", "H17-02=28")


def get(cli, profile, *codes):
    r = cli("--port", "sim", "--profile", profile, "param", "get", *codes, "--json")
    assert r.code == 0, r.err
    return {d["code"]: d.get("text", d["value"]) for d in r.json()}  # an encoded value in the manual's form


def test_sd25_writes_are_ram_only_by_default_and_saved_with_save(cli):
    r = cli("--port", "sim", "--profile", "sd25", "param", "set", "Po109=5", "--json")
    assert r.code == 0 and r.json()["persisted"] is False
    assert "not saved to EEPROM" in cli("--port", "sim", "--profile", "sd25", "param", "set", "Po110=30").err
    r = cli("--port", "sim", "--profile", "sd25", "-v", "param", "set", "Po111=40", "--save", "--json")
    assert r.code == 0 and r.json()["persisted"] is True
    assert ">> 01 06 01 f9 01 00" in r.err and ">> 01 06 01 f9 01 01" in r.err  # Po505.X 1 -> 0 -> 1
    assert cli("sim", "reset", "--profile", "sd25", "--power-cycle").code == 0
    after = get(cli, "sd25", "Po109", "Po110", "Po111", "Po505")
    assert after["Po109"] == 200 and after["Po110"] == 200  # RAM-only writes lost at power-off
    assert after["Po111"] == 40 and after["Po505"] == "d 1 1"  # saved, switch back as the user had it


def test_is620p_stores_by_default_and_no_save_keeps_it_out(cli):
    r = cli("--port", "sim", "--profile", "is620p", "param", "set", "H08-00=30.0", "--json")
    assert r.json()["persisted"] is True
    r = cli("--port", "sim", "--profile", "is620p", "param", "set", "H08-02=50.0", "--no-save", "--json")
    assert r.json()["persisted"] is False
    cli("sim", "reset", "--profile", "is620p", "--power-cycle")
    assert get(cli, "is620p", "H08-00", "H08-02", "H0C-13") == {"H08-00": 30.0, "H08-02": 40.0, "H0C-13": 1}


def test_unchanged_value_touches_neither_parameter_nor_switch_unless_saved(cli):
    r = cli("--port", "sim", "--profile", "sd25", "-v", "param", "set", "Po109=200")
    assert r.code == 0 and ">> 01 06" not in r.err
    # --save cannot know what EEPROM holds, so it stores the value again under the EEPROM setting
    r = cli("--port", "sim", "--profile", "sd25", "-v", "param", "set", "Po109=200", "--save")
    assert r.code == 0 and ">> 01 06 01 f9 01 00" in r.err and "1 value stored in EEPROM" in r.out


SWITCHED = [("sd25", "Po101", "80", "Po505", "d 1 1"), ("is620p", "H08-00", "30.0", "H0C-13", 0)]


@pytest.mark.parametrize(("profile", "code", "value", "switch", "ram"), SWITCHED)
def test_save_after_a_ram_only_write_survives_a_power_cycle(cli, profile, code, value, switch, ram):
    """Defect 1 of issue 14: --save stored nothing when RAM already held the value."""
    default = get(cli, profile, code)[code]
    if profile == "is620p":
        assert cli("--port", "sim", "-P", profile, "param", "set", f"{switch}={ram}").code == 0
    r = cli("--port", "sim", "-P", profile, "param", "set", f"{code}={value}")
    assert r.code == 0 and "not saved to EEPROM" in r.err, r.err
    r = cli("--port", "sim", "-P", profile, "param", "set", "--save", f"{code}={value}", "--json")
    assert r.code == 0 and r.json()["stored"] == [code] and r.json()["persisted"] is True, r.err
    assert cli("sim", "reset", "-P", profile, "--power-cycle").code == 0
    after = get(cli, profile, code, switch)
    assert after[code] == float(value) != default and after[switch] == ram


def test_a_power_cycle_parameter_in_ram_mode_is_refused_with_the_reason(cli):
    before = get(cli, "sd25", "Po407")
    r = cli("--port", "sim", "-P", "sd25", "param", "set", "Po407.X=26")
    assert r.code == 2 and "lost by that power cycle" in r.err and "--save" in r.err
    assert get(cli, "sd25", "Po407") == before  # refused before any write
    r = cli("--port", "sim", "-P", "sd25", "param", "set", "--save", "Po407.X=26", "--json")
    assert r.code == 0 and r.json()["persisted"] is True, r.err


def test_sdc_keeps_modbus_writes_in_ram_and_says_how_to_store_them(cli):
    r = cli("--port", "sim", "--profile", "sdc", "param", "set", "PN17=330", "--json")
    assert r.code == 0 and r.json()["persisted"] is False
    assert "Sn-SEt" in cli("--port", "sim", "--profile", "sdc", "param", "set", "PN18=40").err
    r = cli("--port", "sim", "--profile", "sdc", "param", "set", "PN17=340", "--save")
    assert r.code == 2 and "cannot store parameters over Modbus" in r.err
    assert get(cli, "sdc", "PN17") == {"PN17": 330}  # refused before any write
    assert cli("sim", "reset", "--profile", "sdc", "--power-cycle").code == 0
    assert get(cli, "sdc", "PN17") == {"PN17": 200}  # RAM only, as the manual says (L417)


def test_jog_and_tune_keep_their_writes_out_of_eeprom_on_a_drive_that_stores_every_write(cli):
    """IS620P stores every Modbus write by default (H0C-13 = 1): a JOG or an identification writes its speed
    and ramp many times, so the motion runs with the switch on RAM and puts it back afterwards."""

    def writes() -> int:
        return cli("sim", "show", "--profile", "is620p", "--json").json()["eeprom_writes"]

    cli("--port", "sim", "--profile", "is620p", "param", "set", *IS620P_SETUP)
    before = writes()
    r = cli("--port", "sim", "--profile", "is620p", "jog", "--speed", "300", "--time", "0.5")
    assert r.code == 0, r.err
    r = cli("--port", "sim", "--profile", "is620p", "tune", "inertia", "--yes", "--dry-run", "--json")
    assert r.code == 0, r.err
    assert writes() - before <= 4  # the switch there and back, per motion: not each speed write
    assert get(cli, "is620p", "H0C-13") == {"H0C-13": 1}


def test_tune_says_when_its_result_is_in_ram_only_and_save_stores_it(cli):
    cli("sim", "config", "--profile", "is620p", "--load-ratio", "4")
    cli("--port", "sim", "--profile", "is620p", "param", "set", *IS620P_SETUP, "H0C-13=0")
    # A moderate speed: at the automatic speed a move covers 1.8 of the 2 rev, and a stall of this process on a busy
    # machine (60-200 ms measured) lets the real-time simulated motor run past the travel guard (or, without
    # position feedback, makes the travel integrated from the speed overshoot it). Not issue 16's growing hold
    # oscillation, which is gone (bench/hold_stability.py). This test is about where the result is stored.
    r = cli("--port", "sim", "--profile", "is620p", "tune", "inertia", "--yes", "--max-speed", "600")
    assert r.code == 0 and "not saved to EEPROM" in r.err, r.err
    r = cli(
        "--port", "sim", "--profile", "is620p", "tune", "inertia", "--yes", "--save", "--json", "--max-speed", "600"
    )
    assert r.code == 0 and r.json()["persisted"] is True, r.err
    ratio = get(cli, "is620p", "H08-15")["H08-15"]
    cli("sim", "reset", "--profile", "is620p", "--power-cycle")
    assert get(cli, "is620p", "H08-15", "H0C-13") == {"H08-15": ratio, "H0C-13": 0}  # kept; switch as it was


def test_a_switch_left_changed_by_a_dead_process_is_put_back_by_the_next_command(cli, sim_dir):
    """The host's journal says Po505 was d 1 1 (RAM only) before a process that died changed it to EEPROM."""
    from servotool.connection import ConnectOptions, resolve
    from servotool.ops import journal
    from servotool.session import open_drives

    with open_drives(resolve(ConnectOptions(port="sim", profile="sd25")), notice=lambda _m: None) as (d,):
        d.write_raw(d.profile.entry("Po505"), 0x0100)  # left on EEPROM
        journal.note_switch(d, "Po505", 0x0101)
    (journal.journal_dir() / ".x.json.999999999.abc.tmp").write_text("left by a kill")
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po505", "--json")
    assert r.code == 0 and r.json()[0]["text"] == "d 1 1", r.err
    assert "put Po505 back to d 1 1 (was d 1 0): a servotool process (pid" in r.err
    assert not list(journal.journal_dir().glob("*.json")) and not list(journal.journal_dir().glob("*.tmp"))
    r = cli("--port", "sim", "-P", "sd25", "param", "set", "Po110=30")
    assert r.code == 0 and "not saved to EEPROM" in r.err and "put Po505" not in r.err


def test_writes_of_one_drive_wait_for_another_process_that_has_its_port(cli, sim_dir):
    """Serialised per port: a plain set cannot run while another process has the switch changed for --save."""
    import os
    import subprocess
    import sys
    import time

    from servotool.model.loader import load_profile
    from servotool.ops import journal
    from servotool.session import sim_bus

    class Port:  # what the lock needs of a drive: its bus, profile and unit
        port, unit, profile = sim_bus("sd25"), 1, load_profile("sd25")

    with journal.port_lock(Port()):  # type: ignore[arg-type]
        proc = subprocess.Popen(
            [sys.executable, "-m", "servotool", "--port", "sim", "-P", "sd25", "param", "set", "Po110=30"],
            env=dict(os.environ),
            stderr=subprocess.PIPE,
            text=True,
        )
        time.sleep(4)
        waiting = proc.poll() is None
    assert proc.wait(60) == 0
    assert waiting, "the write did not wait for the port's lock"
    assert get(cli, "sd25", "Po110") == {"Po110": 30}


def _switch_drive(fail_on: int):
    """An IS620P on virtual time, named by a port (so the journal is kept), whose link raises KeyboardInterrupt
    (Ctrl-C) once, right after the drive took the first write of `fail_on` to the switch H0C-13."""
    from servotool.clock import VirtualClock
    from servotool.drive import Drive
    from servotool.model.loader import load_profile
    from servotool.sim.firmware import build_drive
    from servotool.sim.virtual import VirtualLink

    profile = load_profile("is620p")
    clock = VirtualClock()
    link = VirtualLink([build_drive(profile, 1, clock, persist=False)], clock)
    address = profile.entry("H0C-13").address
    real, pending = link.write, [True]

    def write(unit, addr, values, **kw):
        real(unit, addr, values, **kw)
        if addr == address and values == [fail_on] and pending:
            pending.clear()
            raise KeyboardInterrupt  # the reply never read: Ctrl-C came while it was on the line

    link.write = write  # type: ignore[method-assign]
    return Drive(link, profile, 1, port="virtual-line")


@pytest.mark.parametrize(("fail_on", "when"), [(0, "while the switch is changed"), (1, "while it is put back")])
def test_ctrl_c_puts_the_switch_back_and_leaves_no_journal_record(sim_dir, fail_on, when):
    """Issue 14 leftover: Ctrl-C during a --no-save batch left H0C-13 to the journal; now it is put back at once
    while the drive answers, and the interrupt still ends the command."""
    from servotool.ops import eeprom, journal

    d = _switch_drive(fail_on)
    entry = d.profile.entry("H0C-13")
    with pytest.raises(KeyboardInterrupt):
        with eeprom.persistence(d, save=False):
            raise KeyboardInterrupt(when)  # the batch itself is interrupted too (a no-op if already)
    assert d.read_entries([entry])[0].raw == 1, when
    assert journal.read_record(d) is None, when


class IgnoresWrites:
    """A Link that acknowledges writes to one address and drops them (a drive that ignores its EEPROM switch over
    Modbus); `after` writes of other addresses pass first (a drive that drops the switch midway: `revert` then
    puts the switch back behind the host's back)."""

    def __init__(self, link, address: int, *, after: int = 0, revert=None) -> None:
        self.link, self.address, self.after, self.revert = link, address, after, revert
        self.others = 0

    def read(self, unit, address, count, **kw):
        return self.link.read(unit, address, count, **kw)

    def write(self, unit, address, values, **kw):
        if address == self.address and self.revert is None:
            return  # acknowledged, never applied
        self.link.write(unit, address, values, **kw)
        if address != self.address:
            self.others += 1
            if self.revert is not None and self.others == self.after:
                self.revert()

    def close(self):
        self.link.close()


def _ignoring(profile_id: str, **kw):
    """(drive over a link that ignores the profile's EEPROM switch, the simulated drive behind it)."""
    from servotool.clock import VirtualClock
    from servotool.drive import Drive
    from servotool.model.loader import load_profile
    from servotool.sim.firmware import build_drive
    from servotool.sim.virtual import VirtualLink

    profile = load_profile(profile_id)
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    link = IgnoresWrites(VirtualLink([sim], clock), profile.entry(profile.persistence.switch_code).address, **kw)
    return Drive(link, profile, 1, port="virtual-line"), sim


@pytest.mark.parametrize(
    ("profile", "code", "value", "save", "switch_now"),
    [("sd25", "Po003", "20", True, "d 1 1"), ("is620p", "H08-00", "30.0", False, "1 (store)")],
)
def test_a_drive_that_ignores_the_switch_ends_the_set_with_nothing_written(
    sim_dir, profile, code, value, save, switch_now
):
    """Issue 30 item 4: SD25 --save printed "1 value stored in EEPROM" with EEPROM unchanged, IS620P --no-save said
    "not saved" while it was. The switch is read back before any value is written."""
    from servotool.ops import eeprom, journal, params

    d, sim = _ignoring(profile)
    before = (sim.bank.ram[code], sim.bank.eeprom[code])
    plan = params.prepare_set(d, [f"{code}={value}"])
    with pytest.raises(eeprom.SwitchNotTaken) as caught:
        params.set_values(d, plan, save)
    text = str(caught.value)
    assert f"reads back {switch_now} before any value was written: nothing was written" in text, text
    assert caught.value.exit_code == 3
    assert (sim.bank.ram[code], sim.bank.eeprom[code]) == before  # read from the drive's own memory
    assert journal.read_record(d) is None


def test_restore_on_a_drive_that_ignores_the_switch_writes_nothing_and_says_why(sim_dir, tmp_path):
    from servotool.ops import backup, params, restore

    d, sim = _ignoring("sd25")
    target = backup.take(d)
    target.values["Po003"] = 20
    plan = restore.restore_changes(d.profile, target, params.read_settings(d))
    with pytest.raises(restore.RestoreFailed) as caught:
        restore.restore(d, target, plan)
    assert "Po505 (the EEPROM switch)" in str(caught.value) and "nothing was written" in str(caught.value)
    assert caught.value.written == [] and caught.value.equals_backup is True
    assert sim.bank.ram["Po003"] == sim.bank.eeprom["Po003"] == 16


def test_a_plan_save_step_on_a_drive_that_ignores_the_switch_fails(sim_dir, tmp_path):
    from servotool.commission.param_steps import SaveStep
    from servotool.commission.plan import Plan, Step
    from servotool.commission.step_type import RunContext
    from servotool.ops import eeprom, params

    d, sim = _ignoring("sd25")
    params.set_values(d, params.prepare_set(d, ["Po003=20"]), None)  # RAM only, as the plan's set step leaves it
    ctx = RunContext(Plan(tmp_path / "plan.yaml", {}, [1], []), False, True, lambda _i, _q: True)
    ctx.wrote(d, d.profile.entry("Po003"), 20)
    with pytest.raises(eeprom.SwitchNotTaken):
        SaveStep().run(Step(0, 1, "save", None, None), d, ctx)
    assert (sim.bank.ram["Po003"], sim.bank.eeprom["Po003"]) == (20, 16)


def test_a_switch_the_drive_drops_midway_is_reported_with_what_was_written(sim_dir):
    """The switch read again when the writes end: a drive that put it back on its own (here after the first value
    write) leaves the later values in RAM only, and the command must not call them stored."""
    from servotool.ops import eeprom, journal, params

    holder: list = []

    def revert() -> None:  # the drive sets Po505 back to RAM-only by itself
        sim = holder[0]
        sim.bank.ram["Po505"] = sim.bank.eeprom["Po505"] = 0x0101

    d, sim = _ignoring("sd25", after=1, revert=revert)
    holder.append(sim)
    plan = params.prepare_set(d, ["Po003=20", "Po101=30"])
    with pytest.raises(eeprom.SwitchNotTaken) as caught:
        params.set_values(d, plan, True)
    text = str(caught.value)
    assert "when the writes ended: the values written may NOT be" in text, text
    assert "written and verified before it stopped: Po003=20, Po101=30.0" in text, text
    assert sim.bank.eeprom["Po101"] != 300  # stored it was not
    assert journal.read_record(d) is None
