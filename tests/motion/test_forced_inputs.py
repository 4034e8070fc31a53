"""SD25's JOG by forced DIs on virtual time: every non-JOG DI held at its wired level, forcing released on every
exit, and a wired input's change while forced: ignored where the monitor shows the forced levels (the manual's
reading, what servotool says before moving), a stop where the profile says it still shows the terminals."""

from __future__ import annotations

from dataclasses import replace

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.forcing import is_forcing
from servotool.model.loader import load_profile
from servotool.motion.forced_inputs import InputsChanged, wired_inputs_warning
from servotool.motion.jogger import Jogger
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup


def sd25(monitor_shows: str = "forced", **settings):
    profile = load_profile("sd25")
    if monitor_shows != "forced":
        assert profile.forced_inputs is not None
        profile = replace(profile, forced_inputs=replace(profile.forced_inputs, monitor_shows=monitor_shows))
    clock = VirtualClock(20.0)
    sim = build_drive(profile, 1, clock, persist=False)
    make_motion_setup(sim)
    sim.configure(noise=0.0, **settings)
    sim.firmware.reconfigure()
    d = Drive(VirtualLink([sim], clock), profile, 1)
    d.dead_man_waived = True  # SD25 has no dead-man route (--no-dead-man)
    return sim, d, clock


def wire(sim, levels: int):
    """Change the wired inputs (as `sim config --inputs` does for a served drive)."""
    sim.configure(inputs=levels)
    sim.firmware.reconfigure()


def reads(d: Drive, *codes: str) -> list[int]:
    return [r.raw for r in d.read(*codes)]


def test_the_jog_holds_every_other_di_at_its_wired_level_and_releases_forcing(sim_dir):
    sim, d, clock = sd25(inputs=0b1100)  # DI3, DI4 wired closed (say an E-stop and a limit, normally closed)
    seen = []
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(200, 0.6)
    jogger.run(plan, lambda _t, _v: seen.append(tuple(reads(d, "So-57", "L923", "So-58"))))
    assert seen and all(s[0] == 0b1101 and s[1] == 0b1101 and s[2] == 1 for s in seen[1:])  # JOGU + DI3, DI4
    switch, forced = reads(d, "So-58", "So-57")
    assert not is_forcing(d.profile, switch) and forced == 0  # released, the forced value as found
    assert sim.firmware.mode != "jog"


def test_a_wired_change_is_ignored_where_the_monitor_shows_the_forced_levels(sim_dir):
    """The manual's reading (L5249-5253): forcing replaces every DI level, the monitor included, so servotool cannot
    see the wired inputs while it moves; it says so before moving."""
    sim, d, clock = sd25(inputs=0b100)
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(200, 1.0)
    assert "IGNORED" in " ".join(plan.dead_man.limits) and "cannot see them" in " ".join(plan.dead_man.limits)

    def open_di3(t: float, _v: float | None) -> None:
        if t > 0.3:
            wire(sim, 0)

    jogger.run(plan, open_di3)  # runs to its end: the drive ignored DI3 as the manual says
    assert reads(d, "L923") == [0]  # released: the monitor shows the terminals again


def test_a_wired_change_stops_the_jog_where_the_monitor_shows_the_terminals(sim_dir):
    sim, d, clock = sd25("terminals", inputs=0b100, di_monitor=1)
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(200, 3.0)
    assert "servotool watches the input monitor" in wired_inputs_warning(d.profile)
    t_open = []

    def open_di3(t: float, _v: float | None) -> None:
        if t > 0.5 and not t_open:
            t_open.append(clock.now())
            wire(sim, 0)

    with pytest.raises(InputsChanged, match="DI3 changed"):
        jogger.run(plan, open_di3)
    assert clock.now() - t_open[0] < 1.5  # stopped within a beat plus the stop, not after 3 s
    assert abs(jogger.speed() or 0.0) < 5
    assert not is_forcing(d.profile, reads(d, "So-58")[0])


def test_forcing_is_released_when_the_jog_is_interrupted(sim_dir):
    _sim, d, clock = sd25()
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(200, 3.0)

    def interrupt(t: float, _v: float | None) -> None:
        if t > 0.4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        jogger.run(plan, interrupt)
    assert not is_forcing(d.profile, reads(d, "So-58")[0])
    assert abs(jogger.speed() or 0.0) < 5


def test_forcing_found_on_is_released_first_so_that_the_wired_levels_are_read(sim_dir):
    _sim, d, clock = sd25(inputs=0b10000)  # DI5 wired closed
    d.write_raw(d.profile.entry("So-58"), 1)  # left on by the old set-up recipe (forced value 0: DI5 reads open)
    assert reads(d, "L923") == [0]
    jogger = Jogger(d, clock=clock)
    seen = []
    jogger.run(jogger.plan(200, 0.4), lambda _t, _v: seen.append(reads(d, "So-57")[0]))
    assert seen[-1] == 0b10001
    assert not is_forcing(d.profile, reads(d, "So-58")[0])


def test_the_stop_releases_forcing_with_its_zero_command_before_the_motor_is_at_rest(sim_dir):
    """Issue 29 item 6: the wired inputs (an E-stop) act again while the motor ramps down, not only once it rests."""
    _sim, d, clock = sd25()
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(1000, 0.8)
    seen: list[tuple[bool, float]] = []

    def idle(s: float) -> None:
        seen.append((is_forcing(d.profile, reads(d, "So-58")[0]), abs(jogger.speed() or 0.0)))
        clock.sleep(s)

    jogger.idle = idle
    jogger.run(plan)
    released = [i for i, (forcing, _speed) in enumerate(seen) if not forcing]
    assert released and seen[0][0]  # forced while it ran, released at the end
    first = released[0]
    assert all(not forcing for forcing, _ in seen[first:])  # never forced again
    assert seen[first][1] > 100  # released while the motor still turned (it was ramping down from 1000 rpm)
    assert jogger.last_stop is not None and jogger.last_stop.confirmed and "So-58 released" in jogger.last_stop.forcing
