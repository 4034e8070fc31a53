"""kill -9 of a running JOG or identification through `sim serve` (real time, strict simulator): the motor stops
within the bound servotool printed before moving, or, on a drive without a dead-man route, keeps running exactly as
the real drive would (which is why such a drive needs --no-dead-man)."""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time

import pytest

from servotool.model.loader import load_profile
from servotool.model.roles import motion_route
from servotool.motion.deadman import route_of
from servotool.ops.journal import LOOP_ROLES
from tests.reader import Reader

from .test_motion import PROFILES, ROOT, read, set_up

BOUND_RE = re.compile(r"motor stops within ([0-9.]+) rev \(([0-9.]+) s\)")
BOUNDED = [p for p in PROFILES if route_of(load_profile(p)).route != "none"]
UNBOUNDED = [p for p in PROFILES if p not in BOUNDED]


def sample(port: str, profile: str) -> tuple[float, int | None]:
    """(speed rpm, raw position counter or None) read by an independent client (no servotool recovery first)."""
    with Reader(port, profile) as r:
        pos = r.profile.role("position_feedback")
        return r.eng("speed_feedback"), r.raw(pos.code) if pos is not None else None


def moved_rev(profile: str, before: int, after: int) -> float:
    p = load_profile(profile)
    assert p.motor is not None
    step = (after - before) % (1 << 32)
    step = step - (1 << 32) if step >= 1 << 31 else step
    return abs(step) / p.motor.counts_per_rev


def start_motion(port: str, profile: str, *args: str) -> tuple[subprocess.Popen, float, float]:
    """Start a motion command; returns the process and the bound (rev, s) it printed before moving."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "--port", port, "--profile", profile, *args],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if m := BOUND_RE.search(line):
            return proc, float(m.group(1)), float(m.group(2))
        assert line, "the command ended without printing its dead-man bound"
    raise AssertionError("no dead-man bound printed")


def kill_and_measure(
    proc: subprocess.Popen, port: str, profile: str, min_rpm: float, stop_s: float
) -> tuple[float, float]:
    """Wait until the motor runs, kill -9 the command, wait for the bound's time; (rev moved, speed now)."""
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and abs(sample(port, profile)[0]) < min_rpm:
        time.sleep(0.05)
    _speed, before = sample(port, profile)  # read first: the kill comes after, so this over-counts
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(stop_s + 0.3)
    speed, after = sample(port, profile)
    assert before is not None and after is not None
    return moved_rev(profile, before, after), speed


@pytest.mark.parametrize("profile", BOUNDED)
def test_kill_9_of_a_jog_stops_within_the_printed_bound(cli, served_as, profile):
    port = served_as(profile)
    set_up(cli, profile, port)
    proc, rev, s = start_motion(port, profile, "jog", "--speed", "600", "--time", "30", "--yes")
    moved, speed = kill_and_measure(proc, port, profile, 500, s)
    print(f"\n{profile}: moved {moved:.3f} rev after the kill, bound {rev} rev ({s} s), speed now {speed}")
    assert abs(speed) < 10  # stopped
    assert 0 < moved <= rev, (moved, rev)


@pytest.mark.parametrize("profile", BOUNDED)
def test_kill_9_of_an_identification_stops_within_the_printed_bound(cli, served_as, profile):
    port = served_as(profile)
    set_up(cli, profile, port)
    proc, rev, s = start_motion(port, profile, "tune", "inertia", "--yes", "--dry-run", "--max-speed", "300")
    moved, speed = kill_and_measure(proc, port, profile, 100, s)
    print(f"\n{profile}: moved {moved:.3f} rev after the kill, bound {rev} rev ({s} s), speed now {speed}")
    assert abs(speed) < 10
    assert moved <= rev, (moved, rev)


@pytest.mark.parametrize("profile", UNBOUNDED)
def test_a_drive_without_dead_man_refuses_and_a_killed_jog_runs_on_as_the_real_drive(cli, served_as, profile):
    """No route stops the motor: without --no-dead-man nothing moves; with it, kill -9 leaves the (strict)
    simulated motor running, as the real drive would."""
    port = served_as(profile)
    set_up(cli, profile, port)
    r = cli("--port", port, "--profile", profile, "jog", "--speed", "300", "--time", "1", "--yes")
    assert r.code == 2 and "no dead-man on this drive" in r.err and "--no-dead-man" in r.err
    r = cli("--port", port, "--profile", profile, "tune", "inertia", "--yes", "--dry-run")
    assert r.code == 2 and "no dead-man on this drive" in r.err and "keeps running" in r.err
    assert abs(sample(port, profile)[0]) < 10
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "--port",
            port,
            "--profile",
            profile,
            "jog",
            "--speed",
            "300",
            "--time",
            "30",
            "--yes",
            "--no-dead-man",
        ],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and sample(port, profile)[0] < 250:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(1.0)
    assert sample(port, profile)[0] > 250  # nothing on the drive stops it


@pytest.mark.parametrize("profile", BOUNDED)
def test_settings_a_killed_jog_changed_are_put_back_by_the_next_command(cli, served_as, profile):
    """The speed parameter a JOG writes for its duration is journaled: kill -9 mid-JOG leaves it changed on
    the drive (in EEPROM on a drive that stores every write), and the next command puts it back and says so."""
    port = served_as(profile)
    set_up(cli, profile, port)
    entries = motion_route(load_profile(profile), "test").entries
    code = entries["segment_speed" if "segment_speed" in entries else "jog_speed"].code
    gains = [e.code for r in LOOP_ROLES if (e := load_profile(profile).role(r)) is not None]
    before = read(port, code, profile=profile)[0]
    gains_before = read(port, *gains, profile=profile)
    assert before != 700
    proc, _rev, stop_s = start_motion(port, profile, "jog", "--speed", "700", "--time", "30", "--yes")
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and abs(sample(port, profile)[0]) < 600:
        time.sleep(0.05)
    assert read(port, code, profile=profile)[0] == 700  # a second client does not recover a live holder's
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(stop_s + 0.3)
    r = cli("--port", port, "--profile", profile, "param", "get", code)
    assert r.code == 0, r.err
    assert f"put {code} to" in r.err and "ended during a motion" in r.err, r.err
    assert read(port, code, profile=profile)[0] == before
    # A loop gain the JOG lowered (IS620P's hold) waits for the servo to be off: the next JOG puts it back.
    assert cli("--port", port, "--profile", profile, "alarm", "clear").code == 0  # DSX7E's dead-man tripped
    r = cli("--port", port, "--profile", profile, "jog", "--speed", "100", "--time", "0.3", "--yes")
    assert r.code == 0, r.err
    assert read(port, *gains, profile=profile) == gains_before
