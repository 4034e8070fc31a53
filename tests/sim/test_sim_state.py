"""What the CLI learns of and does to a simulated drive outside a Modbus session (servotool.sim.state), directly and
through `servotool sim ...`."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.sim import state
from servotool.sim.firmware import build_drive


def test_a_power_cycle_value_is_in_effect_only_after_a_power_cycle(sim_dir, regs):
    profile = load_profile("dsx7e")
    pn008 = profile.entry("Pn008")
    regs(build_drive(profile, 1)).write("Pn008", 20000)
    assert state.effective_values(profile, 1, [pn008]) == [10000]
    assert state.status(profile, 1).pending_power_cycle == ["Pn008"]
    assert state.power_cycle(profile, 1) == ["Pn008"]
    assert state.effective_values(profile, 1, [pn008]) == [20000]
    assert state.status(profile, 1).pending_power_cycle == []


def test_a_factory_reset_erases_the_drive_and_its_history(sim_dir, regs):
    profile = load_profile("dsx7e")
    clock = VirtualClock(10.0)
    r = regs(build_drive(profile, 1, clock))
    r.write("Pn101", 250)
    r.write("Fn001", 1)  # JOG, then silence: comm timeout into the history
    clock.advance(2.0)
    assert r.read("Un100") and state.status(profile, 1).running is not None
    path = state.factory_reset(profile, 1)
    assert path.parent == sim_dir and not path.exists()
    fresh = regs(build_drive(profile, 1, clock))
    assert fresh.read("Pn101") == profile.entry("Pn101").default and fresh.history() == [0, 0, 0]
    assert state.status(profile, 1).running is None


def test_configure_changes_the_machine_and_refuses_values_out_of_range(sim_dir):
    profile = load_profile("dsx7e")
    status = state.configure(profile, 2, load_ratio=7.5, brake=0, noise=None)
    assert status.unit == 2 and status.settings["load_ratio"] == 7.5 and status.settings["brake"] == 0
    assert state.status(profile, 2).settings == status.settings
    with pytest.raises(UsageError, match="load_ratio"):
        state.configure(profile, 2, load_ratio=-1.0)
    assert state.status(profile, 2).settings["load_ratio"] == 7.5


def test_a_corrupt_state_file_is_an_error_not_silent_factory_defaults(sim_dir, cli):
    assert cli("--port", "sim", "param", "set", "Pn004=400").code == 0
    state_file = sim_dir / "dsx7e-unit1.json"
    good = state_file.read_text()
    for broken in (good[: len(good) // 2], "[1, 2]", '{"profile": "dsx7e", "eeprom_writes": "x"}', "\xff"):
        state_file.write_text(broken, encoding="latin-1")
        r = cli("--port", "sim", "param", "get", "Pn004")
        assert r.code == 1 and "state file" in r.err and "unreadable" in r.err and len(r.err.splitlines()) == 1
        r = cli("--port", "sim", "param", "set", "Pn004=300")
        assert r.code == 1 and state_file.read_text(encoding="latin-1") == broken  # nothing overwritten
    state_file.write_text(good)
    assert cli("--port", "sim", "param", "get", "Pn004", "--json").json()[0]["value"] == 400


def test_an_alarm_latched_by_one_sim_process_is_seen_by_the_next(sim_dir, cli):
    assert cli("sim", "config", "--load-torque", "-1.5", "--brake", "on").code == 0  # pushes forward
    assert cli("--port", "sim", "param", "set", "Pn025=20", "Pn026=20").code == 0  # too weak to hold it
    r = cli("--port", "sim", "jog", "--speed", "100", "--time", "0.5")
    # The drive's own stop at 20 % torque struggles with the load: read back still turning, the stop says so
    # (exit 4); read back at rest once the drive's stop has switched off, the JOG failed with the alarm (exit 1)
    assert "E17" in r.err and (
        (r.code == 4 and "COULD NOT CONFIRM THE MOTOR STOPPED: the speed reads" in r.err)
        or (r.code == 1 and "alarm E17 Overspeed latched" in r.err.splitlines()[-1])
    ), r.err
    r = cli("--port", "sim", "param", "get", "Un100", "Un106", "--json")
    assert [v["value"] for v in r.json()] == [23, 0]  # the current fault; the log keeps those before it
    running = cli("sim", "show", "--json").json()["running"]
    # (whether the drive's own stop at its torque limit has switched off yet depends on when the state was saved)
    assert running["alarm"] == "overspeed" and running["position"]["value"] > 1
    assert "alarm overspeed" in cli("sim", "show").out
    assert cli("sim", "reset", "--power-cycle").code == 0
    r = cli("--port", "sim", "param", "get", "Un100", "Un106", "--json")
    assert [v["value"] for v in r.json()] == [0, 23]  # power on clears the alarm, not the history
    # fresh from power on (the `param get` put back what the unproven stop's journal record held: a write, so a
    # running state is saved, the power-on one)
    running = cli("sim", "show", "--json").json()["running"]
    assert running is None or (
        not running["servo_on"] and running["alarm"] is None and running["position"]["value"] == 0
    )


def test_sim_config_sets_the_brake_and_sim_show_displays_it(cli):
    assert cli("sim", "config", "--brake", "off").code == 0
    r = cli("sim", "show")
    assert r.code == 0 and any("brake" in line and " off " in line for line in r.out.splitlines())
    assert cli("sim", "show", "--json").json()["settings"]["brake"] == 0
    r = cli("sim", "config", "--brake", "maybe")
    assert r.code != 0 and "--brake" in r.err and len(r.err.strip().splitlines()) == 1


def test_sim_reset_factory_removes_the_state_and_reports_it(sim_dir, cli):
    assert cli("--port", "sim", "param", "set", "Pn101=25").code == 0
    r = cli("sim", "reset", "--factory", "--json")
    assert r.code == 0 and r.json() == {
        "profile": "dsx7e",
        "unit": 1,
        "reset": "factory",
        "state_file": str(sim_dir / "dsx7e-unit1.json"),
    }
    assert not (sim_dir / "dsx7e-unit1.json").exists()
    assert cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"] == 18.0


def test_every_simulator_extension_is_listed_and_the_fake_watchdog_is_off_and_labelled(cli):
    """The strict simulator: what it does beyond the manual is listed by sim show and profiles show --unverified;
    the only watchdog a drive without a documented timeout can get is the labelled fake one, off by default."""
    shown = cli("sim", "show", "-P", "sdc", "--json").json()
    assert shown["settings"]["fake_watchdog"] == 0
    # the fake watchdog, and how the friction compensation the manual names switches (issue 34)
    assert [x["what"] for x in shown["extensions"]] == [
        "sim config --fake-watchdog",
        "friction compensation by direction",
    ]
    assert "NOT REAL" in shown["extensions"][0]["why"] and "NOT IN THE MANUAL" in shown["extensions"][1]["why"]
    assert cli("sim", "config", "-P", "sdc", "--fake-watchdog", "on").code == 0
    text = cli("sim", "show", "-P", "sdc").out
    assert "fake_watchdog" in text and "simulator extensions" in text
    dsx = cli("sim", "show", "-P", "dsx7e", "--json").json()["extensions"]
    assert {
        "entry Pn620 (Host communication watchdog timeout)",
        "entry Fn032 (Host keep-alive (any write refreshes the watchdog))",
    } <= {x["what"] for x in dsx}
    assert not any("fake" in x["what"] for x in dsx)  # DSX7E's map documents its watchdog
    r = cli("profiles", "show", "is620p", "--unverified")
    assert "dead-man route: segment" in r.out and "simulator extensions (not in the manual):" in r.out
    assert "SIM.COMM" not in r.out  # the invented alarm is gone
    assert "notch width and depth levels: NOT IN THE MANUAL" in r.out  # the notch's shape is the simulator's
    assert cli("profiles", "show", "sd25", "--json").json()["dead_man"]["route"] == "none"


def test_sim_config_missing_makes_the_drive_lack_entries_until_cleared(cli):
    r = cli("sim", "config", "--missing", "Pn101,pn512", "--json")
    assert r.code == 0 and r.json()["missing"] == ["Pn101", "Pn512"], r.err
    assert cli("sim", "show", "--json").json()["missing"] == ["Pn101", "Pn512"]
    r = cli("--port", "sim", "param", "get", "Pn512")
    assert r.code == 1 and "Pn512: not on this drive" in r.err
    assert cli("sim", "config", "--missing", "", "--json").json()["missing"] == []
    assert cli("--port", "sim", "param", "get", "Pn512").code == 0
    r = cli("sim", "config", "--missing", "Pn9999")
    assert r.code == 2 and "Pn9999" in r.err
