"""Drive firmware behaviour of the simulator on virtual time: watchdog and alarm history."""

from __future__ import annotations

from servotool.profile import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.plant import VirtualClock


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
