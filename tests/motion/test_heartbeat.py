"""The hardware dead-man (--heartbeat dtr|rts): a control line of the USB-RS485 adapter toggled at each keep-alive
beat for a watchdog relay, through a serial-port double that records every change of the line (the real
link.ports.ControlLine sets it); toggles stop when the motion ends, on a late beat and on Ctrl-C."""

from __future__ import annotations

from itertools import pairwise

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.link.ports import ControlLine
from servotool.model.loader import load_profile
from servotool.motion import deadman
from servotool.motion.jogger import Jogger
from servotool.motion.keepalive import HeartbeatMissed
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup


class RecordingPort:
    """A serial port double: its dtr/rts setters record (time, line, level)."""

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock
        self.changes: list[tuple[float, str, bool]] = []
        self._dtr = self._rts = False

    @property
    def dtr(self) -> bool:
        return self._dtr

    @dtr.setter
    def dtr(self, level: bool) -> None:
        self._dtr = level
        self.changes.append((self.clock.now(), "dtr", level))

    @property
    def rts(self) -> bool:
        return self._rts

    @rts.setter
    def rts(self, level: bool) -> None:
        self._rts = level
        self.changes.append((self.clock.now(), "rts", level))


def drive_with_heartbeat(profile_id: str, line: str = "dtr", relay_s: float = 0.5):
    profile = load_profile(profile_id)
    clock = VirtualClock(30.0)
    sim = build_drive(profile, 1, clock, persist=False)
    make_motion_setup(sim)
    sim.configure(noise=0.0)
    sim.firmware.reconfigure()
    d = Drive(VirtualLink([sim], clock), profile, 1)
    port = RecordingPort(clock)
    d.heartbeat_line, d.heartbeat_timeout_s = ControlLine(port, line), relay_s  # type: ignore[arg-type]
    return d, port, clock


@pytest.mark.parametrize("profile", ["sd25", "sdc"])
def test_with_a_heartbeat_a_drive_without_dead_man_moves_bounded_by_the_relay(sim_dir, profile):
    d, port, clock = drive_with_heartbeat(profile)
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(300, 1.0)  # no --no-dead-man: the relay is the dead-man
    assert plan.dead_man.route == "heartbeat" and plan.dead_man.bounded
    assert plan.dead_man.stop_s == pytest.approx(
        0.5 + deadman.stop_time_s(300, plan.accel_ms, d.profile.ramp_rpm()), abs=1e-6
    )
    assert "within" in deadman.sentence(plan.dead_man)
    jogger.run(plan)
    ended = clock.now()
    times = [t for t, name, _level in port.changes if name == "dtr"]
    levels = [level for _t, _name, level in port.changes]
    assert len(times) >= 9  # a toggle a beat (0.1 s) for 1 s
    assert max(b - a for a, b in pairwise(times)) <= 0.5 / 2  # never a gap the relay drops at
    assert all(a != b for a, b in pairwise(levels))  # every change is a toggle
    assert levels[-1] is False and times[-1] <= ended  # low when the motion ended, and no toggle after
    jogger.keepalive.beat()  # a beat after the end (any late caller) toggles nothing
    assert port.changes[-1][0] == times[-1]


def test_a_late_beat_stops_the_heartbeat_and_the_motion(sim_dir):
    d, port, clock = drive_with_heartbeat("sd25", "rts")
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(300, 3.0)
    stalled = []

    def stall(t: float, _v: float | None) -> None:
        if t > 0.5 and not stalled:
            stalled.append(clock.now())
            clock.advance(0.3)  # the host stalls for more than half the relay's time

    with pytest.raises(HeartbeatMissed, match=r"came \d+ ms after the one before"):
        jogger.run(plan, stall)
    assert [name for _t, name, _l in port.changes] == ["rts"] * len(port.changes)
    assert port.changes[-1][2] is False  # left low: the relay times out
    assert max(t for t, _n, level in port.changes if level) < stalled[0]  # not one rising edge after the stall
    assert abs(jogger.speed() or 0.0) < 5  # and the host stopped the JOG too


def test_ctrl_c_stops_the_heartbeat(sim_dir):
    d, port, clock = drive_with_heartbeat("sdc")
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(300, 3.0)

    def interrupt(t: float, _v: float | None) -> None:
        if t > 0.4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        jogger.run(plan, interrupt)
    last = port.changes[-1]
    assert last[2] is False
    clock.advance(1.0)
    assert port.changes[-1] == last


def test_the_heartbeat_is_refused_where_there_is_no_control_line(cli):
    r = cli("--port", "sim", "--heartbeat", "dtr", "param", "get", "Pn004")
    assert r.code == 2 and "sim has none" in r.err
    r = cli("--port", "tcp://127.0.0.1:15299", "-P", "sd25", "--heartbeat", "rts", "jog", "--speed", "100", "-t", "1")
    assert r.code == 2 and "tcp://127.0.0.1:15299 has none" in r.err
    r = cli("--port", "/dev/null", "-P", "sd25", "--heartbeat", "cts", "param", "get", "Po109")
    assert r.code == 2 and "use dtr or rts" in r.err
    short = ("--heartbeat", "dtr", "--heartbeat-timeout-ms", "50")
    r = cli("--port", "/dev/null", "-P", "sd25", *short, "param", "get", "Po109")
    assert r.code == 2 and "200..60000 ms" in r.err


def test_the_heartbeat_comes_from_the_environment_and_the_config_file(cli, tmp_path, monkeypatch):
    monkeypatch.setenv("SERVOTOOL_HEARTBEAT", "dtr")
    r = cli("--port", "sim", "param", "get", "Pn004")
    assert r.code == 2 and "--heartbeat dtr" in r.err
    monkeypatch.delenv("SERVOTOOL_HEARTBEAT")
    config = tmp_path / "config.yaml"
    config.write_text("heartbeat: rts\nheartbeat_timeout_ms: 800\n")
    monkeypatch.setenv("SERVOTOOL_CONFIG", str(config))
    r = cli("--port", "sim", "param", "get", "Pn004")
    assert r.code == 2 and "--heartbeat rts" in r.err
