"""Drive firmware behaviour of the simulator on virtual time: watchdog and alarm history."""

from __future__ import annotations

import math
from dataclasses import replace

from servotool.clock import VirtualClock
from servotool.model.loader import load_profile
from servotool.ops.alarms import describe
from servotool.sim.firmware import build_drive


def write(sim, code: str, raw: int) -> None:
    sim.write(sim.profile.entry(code).address, [raw & 0xFFFF])


def history(sim) -> list[int]:
    return [sim.bank.read(sim.profile.entry(code).address, 1)[0] for code in ("Un106", "Un112", "Un118")]


def test_a_latched_alarm_enters_the_history_once_and_again_after_a_reset(sim_dir):
    clock = VirtualClock(100.0)
    sim = build_drive(load_profile("dsx7e"), 1, clock, persist=False)
    write(sim, "Fn001", 1)                     # JOG forward, then the host goes quiet
    clock.advance(2.0)
    for _ in range(5):                         # the latched alarm is seen on every read, recorded once
        sim.read(sim.profile.entry("Un100").address, 1)
        clock.advance(0.1)
    assert sim.bank.read(sim.profile.entry("Un100").address, 1)[0] == 0x25
    assert history(sim) == [0x25, 0, 0]
    write(sim, "Fn030", 1)                     # alarm reset
    assert sim.bank.read(sim.profile.entry("Un100").address, 1)[0] == 0
    write(sim, "Fn001", -1)
    clock.advance(2.0)
    sim.read(sim.profile.entry("Un100").address, 1)
    assert history(sim) == [0x25, 0x25, 0]


def test_two_processes_on_one_drive_never_undo_each_others_writes(sim_dir):
    profile = load_profile("dsx7e")
    server, cli_side = build_drive(profile, 1), build_drive(profile, 1)     # e.g. sim serve and --port sim
    write(server, "Pn102", 400)
    write(cli_side, "Pn100", 500)              # cli_side saw Pn102 before it changed anything
    write(server, "Pn101", 250)                # and the server sees Pn100 before it saves
    again = build_drive(profile, 1)
    assert [again.bank.value(c) for c in ("Pn100", "Pn101", "Pn102")] == [500, 250, 400]
    cli_side.configure(load_ratio=7.5)         # sim config while the server runs: its plant takes it over
    server.read(profile.entry("Un000").address, 1)
    assert server.firmware.plant.settings.load_ratio == 7.5


def test_a_corrupt_state_file_is_an_error_not_silent_factory_defaults(sim_dir, cli):
    assert cli("--port", "sim", "param", "set", "Pn004=400").code == 0
    state = sim_dir / "dsx7e-unit1.json"
    good = state.read_text()
    for broken in (good[: len(good) // 2], "[1, 2]", '{"profile": "dsx7e", "eeprom_writes": "x"}', "\xff"):
        state.write_text(broken, encoding="latin-1")
        r = cli("--port", "sim", "param", "get", "Pn004")
        assert r.code == 1 and "state file" in r.err and "unreadable" in r.err and len(r.err.splitlines()) == 1
        r = cli("--port", "sim", "param", "set", "Pn004=300")
        assert r.code == 1 and state.read_text(encoding="latin-1") == broken     # nothing overwritten
    state.write_text(good)
    assert cli("--port", "sim", "param", "get", "Pn004", "--json").json()[0]["value"] == 400


def read(sim, code: str) -> int:
    """A monitor read through the drive (integrates the plant up to now), as a signed raw value."""
    entry = sim.profile.entry(code)
    sim.read(entry.address, entry.words)
    return sim.bank.value(entry.code)


def run_for(sim, clock: VirtualClock, seconds: float, every: float = 0.05) -> None:
    for _ in range(round(seconds / every)):
        clock.advance(every)
        read(sim, "Un000")


def holding_drive(load_torque: float, *, brake: bool = True, torque_limit: float = 300.0, without_kind: str = ""):
    """A DSX7E with a gravity load whose Un014 stands in for a following-error monitor (DSX7E has none)."""
    profile = load_profile("dsx7e")
    profile = replace(profile, roles={**profile.roles, "following_error": "Un014"},
                      alarms=[a for a in profile.alarms if a.kind != without_kind])
    clock = VirtualClock(50.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.configure(load_torque=load_torque, brake=int(brake), noise=0.0)
    sim.firmware.reconfigure()
    for code in ("Pn025", "Pn026"):
        write(sim, code, round(torque_limit / sim.profile.entry(code).scale))
    return sim, clock


def test_servo_on_holds_position_against_gravity_through_the_position_loop(sim_dir):
    sim, clock = holding_drive(0.5)
    write(sim, "Pn620", 60000)                           # a 60 s watchdog: nobody sends keep-alives here
    write(sim, "Fn033", 1)                               # servo on, standing still
    run_for(sim, clock, 0.02, every=0.002)
    sag = abs(read(sim, "Un014"))
    assert sim.firmware.plant.mode == "position" and read(sim, "Un100") == 0
    run_for(sim, clock, 1.0)
    counts_per_rev = sim.profile.motor.counts_per_rev
    assert abs(read(sim, "Un012")) < 0.002 * counts_per_rev     # the position loop pulled the sag back
    assert abs(read(sim, "Un014")) < 0.002 * counts_per_rev
    assert sag != 0                                     # the following error was published while the load sagged


def test_gravity_beyond_the_torque_limit_while_holding_ends_in_the_following_error_alarm(sim_dir):
    sim, clock = holding_drive(1.5, torque_limit=100)   # a load the motor cannot hold at 100 %
    write(sim, "Pn620", 60000)
    write(sim, "Fn033", 1)
    run_for(sim, clock, 0.02, every=0.01)
    assert read(sim, "Un100") == 0
    worst = 0
    for _ in range(100):
        clock.advance(0.005)
        worst = max(worst, abs(read(sim, "Un014")))
        if read(sim, "Un100"):
            break
    code = sim.profile.alarm_of_kind("following_error").code
    assert read(sim, "Un100") == code and history(sim)[0] == code
    assert worst > 2.5 * sim.profile.motor.counts_per_rev        # the error grew to the 3 rev default limit
    run_for(sim, clock, 1.0)                            # alarm stop, servo off, the brake closes and holds
    at_rest = read(sim, "Un012")
    run_for(sim, clock, 1.0)
    assert read(sim, "Un012") == at_rest and not sim.firmware.plant.servo_on


def test_the_brake_holds_a_gravity_load_with_servo_off_and_without_it_the_axis_falls(sim_dir):
    sim, clock = holding_drive(0.5, brake=True)
    run_for(sim, clock, 1.0)
    assert read(sim, "Un012") == 0
    sim, clock = holding_drive(0.5, brake=False)
    run_for(sim, clock, 0.2)
    assert read(sim, "Un012") < -sim.profile.motor.counts_per_rev   # falling, only friction against it
    assert read(sim, "Un100") == 0


def test_an_alarm_raised_with_the_servo_off_enters_the_history(sim_dir):
    sim, clock = holding_drive(2.0, brake=False)        # no brake: the load falls until it is over speed
    run_for(sim, clock, 1.0)
    code = sim.profile.alarm_of_kind("overspeed").code
    assert not sim.firmware.plant.servo_on
    assert read(sim, "Un100") == code and history(sim)[0] == code


def test_a_trip_the_profile_lists_no_alarm_for_shows_as_unknown_not_as_another_alarm(sim_dir):
    sim, clock = holding_drive(2.0, brake=False, without_kind="overspeed")
    run_for(sim, clock, 1.0)
    code = read(sim, "Un100")
    state = describe(sim.profile, code)
    assert code and not state.known and code not in {a.code for a in sim.profile.alarms}


def test_the_position_counter_wraps_like_a_multi_turn_counter(sim_dir):
    sim, _clock = holding_drive(0.0)
    counts = sim.profile.motor.counts_per_rev
    sim.firmware.plant.theta = 2 * math.pi * (2**31 + counts // 2) / counts    # half a turn past the top
    assert read(sim, "Un012") == -(2**31) + counts // 2


def test_the_following_error_limit_comes_from_the_drive_parameter_where_it_has_one(sim_dir):
    profile = load_profile("is620p")
    sim = build_drive(profile, 1, VirtualClock(), persist=False)
    assert sim.firmware.plant.gains.following_limit_rev == 3.0      # H0A-10's default: 3 rev of a 20-bit encoder
    entry = profile.entry("H0A-10")
    sim.write(entry.address, [0, 8] if entry.word_order == "low_first" else [8, 0])
    assert sim.firmware.plant.gains.following_limit_rev == 0.5


def test_a_latched_alarm_and_the_motion_state_survive_into_another_process(sim_dir):
    profile = load_profile("dsx7e")
    clock = VirtualClock(100.0)
    first = build_drive(profile, 1, clock)
    write(first, "Fn001", 1)                   # JOG forward, then the host goes quiet: comm timeout
    clock.advance(2.0)
    read(first, "Un100")
    second = build_drive(profile, 1, clock)    # e.g. the next `--port sim` command
    assert read(second, "Un100") == 0x25 and history(second)[0] == 0x25
    write(second, "Fn030", 1)                  # reset in the second, running JOG there, seen by the first
    write(second, "Fn001", 1)
    clock.advance(0.1)
    assert read(first, "Un100") == 0 and first.firmware.mode == "jog" and read(first, "Un000") > 0
    position = read(first, "Un012")
    assert position > 0 and read(build_drive(profile, 1, clock), "Un012") == position
    second.power_cycle()                       # power off and on: the running state starts afresh
    assert read(first, "Un012") == 0 and first.firmware.mode == "off" and history(first)[0] == 0x25


def test_an_alarm_latched_by_one_sim_process_is_seen_by_the_next(sim_dir, cli):
    assert cli("sim", "config", "--load-torque", "-1.5", "--brake", "on").code == 0     # pushes forward
    assert cli("--port", "sim", "param", "set", "Pn025=20", "Pn026=20").code == 0      # too weak to hold it
    r = cli("--port", "sim", "jog", "--speed", "100", "--time", "0.5")
    assert r.code == 1 and "E17" in r.err
    r = cli("--port", "sim", "param", "get", "Un100", "Un106", "--json")
    assert [v["value"] for v in r.json()] == [23, 23]
    running = cli("sim", "show", "--json").json()["running"]
    assert running["alarm"] == "overspeed" and not running["servo_on"] and running["position_rev"] > 1
    assert "alarm overspeed" in cli("sim", "show").out
    assert cli("sim", "reset", "--power-cycle").code == 0
    r = cli("--port", "sim", "param", "get", "Un100", "Un106", "--json")
    assert [v["value"] for v in r.json()] == [0, 23]            # power on clears the alarm, not the history
    assert cli("sim", "show", "--json").json()["running"] is None             # fresh from power on


def test_sim_config_sets_the_brake_and_sim_show_displays_it(cli):
    assert cli("sim", "config", "--brake", "off").code == 0
    r = cli("sim", "show")
    assert r.code == 0 and any("brake" in line and " off " in line for line in r.out.splitlines())
    assert cli("sim", "show", "--json").json()["settings"]["brake"] == 0
    r = cli("sim", "config", "--brake", "maybe")
    assert r.code != 0 and "--brake" in r.err and len(r.err.strip().splitlines()) == 1


def test_a_servo_on_by_parameter_stays_on_and_only_commanded_motion_is_watched(sim_dir):
    """SDC documents no comm timeout: the simulator's assumed watchdog stops host-commanded motion only."""
    profile = load_profile("sdc")
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    write(sim, "PN4", 3)                                 # speed mode (the JOG route's setup)
    write(sim, "PN95", 1)                                # servo on, nothing commanded
    for _ in range(20):                                  # far beyond the assumed 500 ms, no host traffic
        clock.advance(0.1)
        read(sim, "UN-1")
    assert sim.firmware.plant.servo_on and read(sim, "UN-21") == 0
    write(sim, "PN22", 300)                              # commanded motion ...
    for _ in range(10):                                  # ... and then silence
        clock.advance(0.1)
        read(sim, "UN-1")
    code = profile.alarm_of_kind("comm_timeout").code
    assert read(sim, "UN-21") == code and not sim.firmware.plant.servo_on


def test_sd25_reports_servo_on_and_motion_in_its_do_function_state_word(sim_dir):
    """SD25 has no status word: its DO-function state (944: SON-O, TGON, ALM) serves as one, by bit name."""
    profile = load_profile("sd25")
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    status = profile.role("servo_status")
    assert read(sim, status.code) == 0
    sim.firmware.plant.set_mode("speed")                 # servo on (as JOG does), turning
    sim.firmware.plant.set_speed_command(300)
    for _ in range(5):
        clock.advance(0.05)
        read(sim, "L904")
    word = read(sim, status.code)
    assert word & 0b110 == 0b110 and not word & (1 << 6)     # SON-O and TGON set, ALM clear


def _jog_forward(sim, clock: VirtualClock) -> float:
    """Command forward host motion by the profile's route (JOG trigger, or servo-on + speed reference); speed after."""
    p = sim.profile
    if p.role("jog") is not None:
        write(sim, p.roles["jog"], 1)
    else:
        write(sim, p.roles["servo_on"], 1)
        write(sim, p.roles["speed_reference"], 300)
    for _ in range(10):                              # the keep-alive a host would send
        clock.advance(0.05)
        write(sim, p.roles.get("jog") or p.roles["servo_on"], 1)
    return read(sim, p.roles["speed_feedback"]) * p.role("speed_feedback").scale


def test_host_motion_writes_move_nothing_until_the_drive_is_set_up(sim_dir):
    """A third-party master writing the motion registers of a drive not set up sees it stand still, as a real
    drive would; after the setup (and, for SD25, the power cycle) the same writes move it."""
    setups = {"is620p": {"H02-00": 0, "H0C-09": 1, "H17-00": 1}, "sdc": {"PN4": 3},
              "sd25": {"Po407": 26, "Po408": 27, "So-58": 1}}
    for pid, setup in setups.items():
        clock = VirtualClock(10.0)
        sim = build_drive(load_profile(pid), 1, clock, persist=False)
        assert abs(_jog_forward(sim, clock)) < 1 and sim.firmware.mode == "off", pid
        for code, raw in setup.items():
            write(sim, code, raw)
        if pid == "sd25":
            assert abs(_jog_forward(sim, clock)) < 1, "Po407/Po408 act only after a power cycle"
            sim.bank.save_eeprom()            # what `param set --save` does; So-58 is set again after power-up
            sim.power_cycle()
            write(sim, "So-58", 1)
        assert _jog_forward(sim, clock) > 100, pid
