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
