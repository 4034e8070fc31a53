"""Every way out of a motion, through the real CLI and `sim serve`, judged by a plain Modbus client (pymodbus,
bench/plain_reader.py): a seeded sample of bench/ctrl_c_storm.py (a few Ctrl-C moments and a kill -9 per profile),
`servotool stop`, and the safety lines that --quiet does not hide. The invariants are asserted, not timings."""

from __future__ import annotations

import json
import random
import subprocess
import sys
import time

import pytest

from bench.ctrl_c_storm import COMMANDS, GAINS, PROFILES, ROOT, Served, interrupt, kill, no_dead_man
from bench.plain_reader import PlainReader


@pytest.fixture
def served(tmp_path):
    started: list[Served] = []

    def start(profile: str) -> Served:
        s = Served(profile, tmp_path / profile)
        s.start()
        started.append(s)
        s.set_up()
        return s

    yield start
    for s in started:
        s.close()


@pytest.mark.parametrize("profile", PROFILES)
def test_ctrl_c_at_seeded_moments_and_kill_9_leave_the_drive_as_the_bench_requires(served, profile):
    s = served(profile)
    rng = random.Random(29)
    outcomes = [interrupt(s, "jog", rng.uniform(0.2, 2.0)) for _ in range(2)]
    outcomes.append(interrupt(s, "ident", rng.uniform(0.5, 2.0)))
    outcomes.append(kill(s, "jog", 0.2))
    failures = [f"{o.kind}: {o.why}" for o in outcomes if not o.ok]
    assert not failures, failures


# A Ctrl-C at a named point (bench/interrupt_at.py raises SIGINT in the process there), and how the command's last
# line must begin: before anything moved the read-back alone; once a motion's scope began, its stop.
NAMED_POINTS = (
    ("step", "bound", "servotool: nothing moved: at rest, servo off"),  # plan lines and pre-motion reads to come
    ("gains", "step-check", "servotool: nothing moved: at rest, servo off"),  # a level's gains written, not checked
    ("jog", "bound", "servotool: nothing moved: at rest, servo off"),
    ("ident", "snapshot", "servotool: stopped, servo off"),  # its settings journaled, nothing written
    ("gains", "protections", "servotool: stopped, servo off"),  # the drive's protections written, not moved
)


@pytest.mark.parametrize("profile", ["sdc", "dsx7e"])
def test_ctrl_c_before_the_motor_moves_ends_with_the_drive_read_back_and_everything_put_back(served, profile):
    """Issue 29 follow-up: a Ctrl-C after the bound line but before the first motion (0.1-0.3 s on SDC at 9600 baud)
    exited 130 with 'servotool: interrupted' and no read-back. Delivered at named points, not moments: every one ends
    with exit 130 and the drive read back, and a plain Modbus client reads it at rest, servo off, every parameter
    as before (gains, protections, JOG speed and ramp), and nothing left for the next command to put right."""
    s = served(profile)
    with PlainReader(s.port, profile) as reader:
        found = reader.settings()
    failures = []
    for kind, point, last in NAMED_POINTS:
        json_out = ["--json"] if kind == "jog" else []
        command = [*COMMANDS[kind], *no_dead_man(profile), *json_out]
        r = subprocess.run(
            [sys.executable, str(ROOT / "bench" / "interrupt_at.py"), point, "--port", s.port, "-P", profile, *command],
            cwd=ROOT,
            env=s.env,
            capture_output=True,
            text=True,
            timeout=120,
        )
        lines = [line for line in r.stderr.splitlines() if line.strip()]
        snap = s.read()
        where = f"{kind} at {point}"
        if r.returncode != 130 or not lines or not lines[-1].startswith(last):
            failures.append(f"{where}: exit {r.returncode}, last line {lines[-1] if lines else '(none)'}")
        if abs(snap.speed_rpm) >= 10 or snap.servo_on or snap.alarm:
            failures.append(f"{where}: the plain reader reads {snap}")
        if json_out and r.returncode == 130:
            stop = json.loads(r.stdout).get("stop") or {}
            if not (stop.get("confirmed") and stop.get("moved") is False and stop.get("servo_on") is False):
                failures.append(f"{where}: --json stop {stop}")
        after = s.cli("param", "get", GAINS[profile][0])  # the journal left nothing to put right
        if after.returncode != 0 or "pid " in after.stderr:
            failures.append(f"{where}: the next command said {after.stderr.strip()[-200:]}")
    with PlainReader(s.port, profile) as reader:
        left = {code: raw for code, raw in reader.settings().items() if found[code] != raw}
    assert not failures, failures
    assert not left, f"written and not put back: {left} (found { ({c: found[c] for c in left}) })"


def test_servotool_stop_stops_a_motor_another_process_left_running_and_releases_forcing(served):
    """SD25 JOGs by forcing DIs: kill -9 leaves JOGU forced on and the motor running (no dead-man); `servotool stop`
    zeroes the JOG word, releases forcing (So-58) and proves it, with no identity check or journal first."""
    s = served("sd25")
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "--port",
            s.port,
            "-P",
            "sd25",
            "jog",
            "--speed",
            "300",
            "--time",
            "30",
            "--yes",
            "--no-dead-man",
        ],
        env=s.env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and abs(s.read().speed_rpm) < 250:
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    time.sleep(0.5)
    assert abs(s.read().speed_rpm) > 250  # nothing on the drive stops it
    r = s.cli("--no-identity-check", "stop", "--json")
    assert r.returncode == 0, r.stderr
    [unit] = json.loads(r.stdout)
    assert unit["confirmed"] and unit["forcing"] == "So-58 released"
    snap = s.read()
    assert abs(snap.speed_rpm) < 10 and not snap.servo_on and snap.forcing == 0


def test_a_drive_that_does_not_answer_is_said_in_capitals_with_exit_4(served):
    s = served("dsx7e")
    r = s.cli("--timeout", "0.2", "--retries", "0", "-u", "9", "stop")  # no unit 9 on this line
    assert r.returncode == 4
    assert "unit 9: COULD NOT CONFIRM THE MOTOR STOPPED" in r.stderr


def test_the_safety_lines_are_not_hidden_by_quiet_and_are_in_json(served):
    s = served("sdc")
    r = s.cli("-q", "jog", "--speed", "100", "--time", "0.3", "--yes", "--no-dead-man", "--json")
    assert r.returncode == 0, r.stderr
    assert "NO DEAD-MAN (--no-dead-man)" in r.stderr  # printed with -q
    assert r.stderr.strip().splitlines()[-1].startswith("servotool: stopped, servo off")
    data = json.loads(r.stdout)
    assert any(line.startswith("NO DEAD-MAN") for line in data["safety"])
    assert data["stop"]["confirmed"] and data["stop"]["servo_on"] is False
    with PlainReader(s.port, "sdc") as reader:
        assert not reader.servo_on()


def test_a_jog_whose_run_on_does_not_fit_its_travel_is_refused_naming_what_fits(served):
    s = served("dsx7e")
    r = s.cli("jog", "--speed", "600", "--time", "0.2", "--travel", "3", "--yes")
    assert r.returncode == 2
    assert "could run on 5.20 rev" in r.stderr and "--speed" in r.stderr and "Pn620" in r.stderr
    assert abs(s.read().speed_rpm) < 10  # nothing moved
