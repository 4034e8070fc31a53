"""The drive's own protections, set for a motion's duration and put back, judged through `sim serve` by an
independent reader (tests/reader.py: plain pymodbus, no servotool recovery): during a JOG, after it, after kill -9
and the next command; SD25's overtravel fence stopping a dead host's JOG; SD25's forced inputs released after
Ctrl-C and kill -9."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from servotool.model.forcing import is_forcing
from servotool.motion.protect import SPEED_LIMIT_MARGIN
from tests.reader import Reader

from .test_motion import ROOT, ack, set_up

SPEED = 300.0
# Per profile: the entries a JOG at SPEED sets (raw values as the reader sees them during the motion).
DURING = {
    "dsx7e": {"Pn027": round(SPEED * SPEED_LIMIT_MARGIN)},
    "is620p": {"H06-07": round(SPEED * SPEED_LIMIT_MARGIN)},
    "sdc": {"PN20": round(SPEED * SPEED_LIMIT_MARGIN), "PN65": 200, "PN79": 50, "PN120": 0},
    "sd25": {"So-39": 2, "So-34": 1, "So-40": 50, "Po142": 20, "Po145": 20},
}


def travel(profile: str) -> list[str]:
    """SD25's fence follows the travel limit (--travel 20); SDC has no position monitor for one."""
    return ["--travel", "20"] if profile == "sd25" else []


def jog(port: str, profile: str, *args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "servotool", "--port", port, "--profile", profile, "jog", *args, "--yes", *ack(profile)],
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )


def wait_running(r: Reader, rpm: float, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if abs(r.eng("speed_feedback")) >= rpm:
            return
        time.sleep(0.05)
    raise AssertionError(f"the motor never reached {rpm} rpm")


def wait_standing(r: Reader, timeout_s: float = 5.0) -> float:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if abs(speed := r.eng("speed_feedback")) < 5:
            return speed
        time.sleep(0.05)
    return r.eng("speed_feedback")


def forcing(r: Reader) -> bool:
    return is_forcing(r.profile, r.raw("So-58"))


@pytest.mark.parametrize("profile", ["sd25", "sdc", "is620p", "dsx7e"])
def test_a_jog_sets_the_drives_protections_and_puts_them_back(cli, served_as, profile):
    port = served_as(profile)
    set_up(cli, profile, port)
    with Reader(port, profile) as r:
        codes = list(DURING[profile])
        before = {c: r.raw(c) for c in codes}
        assert before != DURING[profile]
        proc = jog(port, profile, "--speed", f"{SPEED:g}", "--time", "3", *travel(profile))
        wait_running(r, SPEED * 0.9)
        during = {c: r.raw(c) for c in codes}
        if profile == "sd25":  # the fence around where the JOG started, its inputs forced
            assert forcing(r)
        _out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert {c: r.raw(c) for c in codes} == before
        assert abs(r.eng("speed_feedback")) < 10
        if profile == "sd25":
            assert not forcing(r) and r.raw("So-57") == 0
    assert during == DURING[profile], err
    assert "overtravel fence" in err if profile == "sd25" else f"speed limit {codes[0]}" in err


@pytest.mark.parametrize("profile", ["sd25", "sdc"])
def test_a_killed_jogs_protections_are_put_back_by_the_next_command(cli, served_as, profile):
    port = served_as(profile)
    set_up(cli, profile, port)
    with Reader(port, profile) as r:
        codes = list(DURING[profile])
        before = {c: r.raw(c) for c in codes}
        proc = jog(port, profile, "--speed", f"{SPEED:g}", "--time", "3", *travel(profile))
        wait_running(r, SPEED * 0.9)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        time.sleep(0.3)
        assert {c: r.raw(c) for c in codes} == DURING[profile]  # nothing on the drive put them back
        assert abs(r.eng("speed_feedback")) > SPEED * 0.9  # neither drive documents a dead-man: it runs on
        if profile == "sdc":
            r.write("PN95", 0)  # stopped at the drive (its enable), by someone else than servotool
            assert wait_standing(r) == pytest.approx(0, abs=5)  # before the next command: it finds it standing
        else:
            assert forcing(r)
        first = cli("--port", port, "--profile", profile, "param", "get", codes[0])
        assert first.code == 0, first.err
        if profile == "sd25":  # releasing the forced inputs is what stops the JOG: first, moving or not
            assert "released the drive's forced inputs (So-58 = d 0 0)" in first.err, first.err
            assert not forcing(r)
        assert wait_standing(r) == pytest.approx(0, abs=5)
        if profile == "sd25":  # the settings wait for a command that finds the motor standing
            again = cli("--port", port, "--profile", profile, "param", "get", codes[0])
            assert again.code == 0, again.err
            first = again if "put" in again.err else first
        assert "ended during a motion" in first.err and f"put {codes[0]} to" in first.err, first.err
        assert {c: r.raw(c) for c in codes} == before


def test_sd25s_fence_stops_a_dead_hosts_jog(cli, served_as):
    """No dead-man on SD25: a killed JOG's forced JOGU stays on. The overtravel fence servotool set around the start
    (So-39 = stop, --travel 6) stops it there, where it would otherwise run until stopped at the drive."""
    port = served_as("sd25")
    set_up(cli, "sd25", port)
    with Reader(port, "sd25") as r:
        start = r.raw("L938") + r.raw("L936") / 131072
        proc = jog(port, "sd25", "--speed", "300", "--time", "1", "--travel", "6")
        wait_running(r, 250)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        err = proc.stderr.read() if proc.stderr else ""
        time.sleep(1.8)  # 5 rev/s: the fence is at most 6 rev from the start
        # settling at the fence may still read a few rpm on a busy host (5.7 seen once); a motor the fence did not
        # stop is past 6.1 rev by then, which the travel below fails
        assert abs(wait_standing(r, 3.0)) < 5, "still running: the fence did not stop it"
        moved = r.raw("L938") + r.raw("L936") / 131072 - start
        assert 5.0 < moved <= 6.1, moved
        assert r.raw("L926") == 0  # stopped without an alarm (So-39 = 2)
        assert forcing(r)  # still forced: the dead process left it
    assert "until the drive's overtravel fence at ±6.00 rev stops it" in err, err
    r2 = cli("--port", port, "--profile", "sd25", "param", "get", "So-39")
    assert "released the drive's forced inputs" in r2.err


def test_sd25s_forced_inputs_are_released_after_ctrl_c(cli, served_as):
    port = served_as("sd25")
    set_up(cli, "sd25", port)
    with Reader(port, "sd25") as r:
        r.write("So-57", 0b1000_0000)  # a forced value left by someone: put back as found
        proc = jog(port, "sd25", "--speed", "300", "--time", "5")
        wait_running(r, 250)
        assert forcing(r) and r.raw("So-57") == 0b01  # JOGU, every other DI at its wired level (none closed)
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=20)
        assert proc.returncode == 130, err
        assert not forcing(r) and r.raw("So-57") == 0b1000_0000
        assert wait_standing(r) == pytest.approx(0, abs=5)


def test_an_identification_sets_them_for_its_duration_too(cli, served_as):
    """SDC through `tune inertia`: the speed limit near the test speed, the saturation trip and the overload multiple
    while it moves, the drive's own values after it."""
    port = served_as("sdc")
    set_up(cli, "sdc", port)
    with Reader(port, "sdc") as r:
        codes = ("PN20", "PN65", "PN79", "PN120")
        before = {c: r.raw(c) for c in codes}
        tune = ["tune", "inertia", "--yes", "--dry-run", "--no-dead-man", "--max-speed", "600"]
        proc = subprocess.Popen(
            [sys.executable, "-m", "servotool", "--port", port, "-P", "sdc", *tune],
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        wait_running(r, 100)
        during = {c: r.raw(c) for c in codes}
        fastest = abs(r.eng("speed_feedback"))
        _out, err = proc.communicate(timeout=120)
        after = {c: r.raw(c) for c in codes}
    assert fastest <= during["PN20"] <= 600 * SPEED_LIMIT_MARGIN + 1, (during, err)
    assert (during["PN65"], during["PN79"], during["PN120"]) == (200, 50, 0)
    assert after == before, err
    assert "the drive's speed limit PN20 at" in err and "trips AL-6 after 0.5 s" in err
