"""One simulated drive served by several processes in turn (sim serve, each `--port sim` command, sim config): each
continues the running machine the last one left, and a power cycle starts it afresh."""

from __future__ import annotations

from servotool.clock import VirtualClock
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive


def test_two_processes_on_one_drive_never_undo_each_others_writes(sim_dir, regs):
    profile = load_profile("dsx7e")
    server, cli_side = build_drive(profile, 1), build_drive(profile, 1)  # e.g. sim serve and --port sim
    regs(server).write("Pn102", 400)
    regs(cli_side).write("Pn100", 500)  # cli_side saw Pn102 before it changed anything
    regs(server).write("Pn101", 250)  # and the server sees Pn100 before it saves
    again = regs(build_drive(profile, 1))
    assert [again.read(c) for c in ("Pn100", "Pn101", "Pn102")] == [500, 250, 400]
    cli_side.configure(load_ratio=7.5)  # sim config while the server runs: its plant takes it over
    regs(server).read("Un000")
    assert server.firmware.plant.settings.load_ratio == 7.5


def test_a_latched_alarm_and_the_motion_state_survive_into_another_process(sim_dir, regs):
    profile = load_profile("dsx7e")
    clock = VirtualClock(100.0)
    first = regs(build_drive(profile, 1, clock))
    first.write("Fn001", 1)  # JOG forward, then the host goes quiet: comm timeout
    clock.advance(2.0)
    first.read("Un100")
    second = regs(build_drive(profile, 1, clock))  # e.g. the next `--port sim` command
    assert second.read("Un100") == 0x25 and second.drive.firmware.alarms.records()[0]["code"] == 0x25
    second.write("Fn030", 1)  # reset in the second, running JOG there, seen by the first
    assert second.history()[0] == 0x25
    second.write("Fn001", 1)
    clock.advance(0.1)
    assert first.read("Un100") == 0 and first.drive.firmware.mode == "jog" and first.read("Un000") > 0
    position = first.read("Un012")
    assert position > 0 and regs(build_drive(profile, 1, clock)).read("Un012") == position
    second.drive.power_cycle()  # power off and on: the running state starts afresh
    assert first.read("Un012") == 0 and first.drive.firmware.mode == "off" and first.history()[0] == 0x25


def test_an_identification_started_in_one_process_finishes_in_the_next(sim_dir, regs):
    profile = load_profile("dsx7e")
    clock = VirtualClock(10.0)
    first = regs(build_drive(profile, 1, clock))
    before = first.read("Pn004")
    first.write("Fn008", 1)  # start the drive's own identification
    clock.advance(0.05)
    first.read("Un000")
    assert first.drive.firmware.mode == "ident"
    second = regs(build_drive(profile, 1, clock))
    assert second.drive.firmware.mode == "ident"
    for _ in range(100):
        clock.advance(0.05)
        second.read("Un000")
    assert second.drive.firmware.mode == "off" and second.read("Un100") == 0
    assert second.read("Pn004") != before and first.read("Pn004") == second.read("Pn004")
