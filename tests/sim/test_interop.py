"""Interop: `servotool sim serve` on one end of a socat pty pair, a third-party master (mbpoll/libmodbus)
and servotool's own client on the other end."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(not (shutil.which("socat") and shutil.which("mbpoll")),
                                reason="needs socat and mbpoll (installed by .ci/run)")

ROOT = Path(__file__).resolve().parents[2]


def _wait_for(path: Path, seconds: float = 5) -> None:
    end = time.monotonic() + seconds
    while not path.exists():
        if time.monotonic() > end:
            raise TimeoutError(path)
        time.sleep(0.05)


@pytest.fixture
def pty_line(tmp_path, sim_dir):
    """(drive side, master side) of a pty pair with two simulated drives (units 1 and 2) serving."""
    a, b = tmp_path / "drive", tmp_path / "master"
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"],
                             stderr=subprocess.DEVNULL)
    _wait_for(a)
    _wait_for(b)
    server = subprocess.Popen([sys.executable, "-m", "servotool", "sim", "serve", "--port", str(a), "--baud", "19200",
                               "--unit", "1", "--unit", "2"], cwd=ROOT, stderr=subprocess.PIPE, text=True,
                              env=dict(os.environ))
    line = server.stderr.readline()
    assert "serving on" in line, line
    yield a, b
    server.terminate()
    server.wait(timeout=10)
    socat.terminate()
    socat.wait(timeout=10)



def read(port: Path, ref: int, count: int = 1, unit: int = 1) -> list[int]:
    proc = subprocess.run(["mbpoll", "-m", "rtu", "-a", str(unit), "-b", "19200", "-P", "none", "-t", "4", "-0", "-1",
                           "-o", "1", "-r", str(ref), "-c", str(count), str(port)],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return [int(ln.split(":")[1]) for ln in proc.stdout.splitlines() if ln.startswith("[")]


def write(port: Path, ref: int, *values: int, unit: int = 1) -> subprocess.CompletedProcess:
    return subprocess.run(["mbpoll", "-m", "rtu", "-a", str(unit), "-b", "19200", "-P", "none", "-t", "4", "-0", "-1",
                           "-o", "1", "-r", str(ref), str(port), *map(str, values)],
                          capture_output=True, text=True, timeout=30)


def test_mbpoll_reads_and_writes_documented_addresses(pty_line):
    _, master = pty_line
    assert read(master, 0x2004) == [250]                 # Pn004 load inertia ratio default
    assert read(master, 0x2008, 2) == [10000, 0]         # Pn008 u32, low word first
    assert read(master, 0x2100, 3) == [320, 180, 310]    # Pn100..Pn102 in one request
    ok = write(master, 0x2004, 300)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert read(master, 0x2004) == [300]
    assert read(master, 0x2004, unit=2) == [250]         # the second drive on the line is separate
    two = write(master, 0x2008, 20000, 0)                # FC16 over both words
    assert two.returncode == 0
    assert read(master, 0x2008, 2) == [20000, 0]


def test_mbpoll_gets_exception_responses(pty_line):
    _, master = pty_line
    out_of_range = write(master, 0x2004, 50)           # Pn004 min is 100
    assert out_of_range.returncode != 0 and "Illegal data value" in out_of_range.stderr
    unmapped = subprocess.run(["mbpoll", "-m", "rtu", "-a", "1", "-b", "19200", "-P", "none", "-t", "4", "-0", "-1",
                               "-o", "1", "-r", "100", "-c", "1", str(master)], capture_output=True, text=True,
                              timeout=30)
    assert unmapped.returncode != 0 and "Illegal data address" in unmapped.stderr
    read_only = write(master, 0x4000, 5)                # Un000 motor speed
    assert read_only.returncode != 0 and "Illegal data address" in read_only.stderr
    assert read(master, 0x2004) == [250]                # nothing changed


def test_servotool_client_over_the_same_line(pty_line, cli):
    _, master = pty_line
    base = ("--port", str(master), "--baud", "19200", "--profile", "dsx7e")
    r = cli(*base, "param", "set", "Pn101=22.5")
    assert r.code == 0, r.err
    assert read(master, 0x2101) == [225]
    r = cli(*base, "--unit", "2", "param", "get", "Pn101", "--json")
    assert r.code == 0 and r.json()[0]["value"] == 18.0
    r = cli(*base, "--unit", "7", "--timeout", "0.2", "--retries", "0", "param", "get", "Pn101")
    assert r.code == 1 and "no response within" in r.err
