"""`sim serve` ends on a terminate or hang-up signal as at Ctrl-C (exit 130, "simulator stopped"), whatever its
event loop is doing: a master's requests in flight, replies held back by the line emulation."""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _serve(env: dict[str, str]) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0", "--profile", "sdc"],
        cwd=ROOT,
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    found = re.search(r"(tcp://127\.0\.0\.1:\d+)", proc.stderr.readline())
    assert found, "sim serve did not say where it serves"
    return proc, found.group(1)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
@pytest.mark.parametrize("name", ["SIGTERM", "SIGHUP"])
def test_a_terminate_signal_during_traffic_ends_sim_serve_as_ctrl_c_does(sim_dir, name):
    env = {**os.environ, "SERVOTOOL_SIM_DIR": str(sim_dir)}
    rng = random.Random(name)
    for _ in range(3):
        proc, port = _serve(env)
        master = subprocess.Popen(
            [sys.executable, "-m", "servotool", "--port", port, "-P", "sdc", "monitor", "--count", "500"],
            cwd=ROOT,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            time.sleep(rng.uniform(1.0, 2.0))  # the master is past its start-up and exchanging at 9600 baud
            proc.send_signal(getattr(signal, name))
            try:
                status = proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
                pytest.fail(f"sim serve still ran 20 s after {name}")
            assert proc.stderr is not None
            said = proc.stderr.read()
            assert status == 130, said
            assert "servotool: simulator stopped" in said
        finally:
            master.kill()
            master.wait()
            if proc.poll() is None:
                proc.kill()
                proc.wait()
