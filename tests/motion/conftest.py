"""Fixtures of the motion tests: `servotool sim serve` on a free loopback port, for a second process to use."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def serve(profile: str):
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0", "--profile", profile],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONFAULTHANDLER": "1"},  # SIGABRT prints its threads' stacks (end() below)
    )
    line = proc.stderr.readline()
    m = re.search(r"(tcp://127\.0\.0\.1:\d+)", line)
    assert m, line
    return proc, m.group(1)


def end(proc: subprocess.Popen) -> None:
    """Terminate a served drive; one that has not ended 10 s later fails the test with its threads' stacks (a
    terminate once went unanswered for 10 s in CI: the stacks say where it waited)."""
    proc.terminate()
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGABRT)
        try:
            _out, said = proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            _out, said = proc.communicate()
        pytest.fail(f"sim serve still ran 10 s after SIGTERM; its stacks:\n{said[-4000:]}")


@pytest.fixture
def served(sim_dir):
    """`servotool sim serve` (DSX7E) on a free loopback port; yields its tcp:// address."""
    proc, port = serve("dsx7e")
    yield port
    end(proc)


@pytest.fixture
def served_as(sim_dir):
    """Start `servotool sim serve --profile P`; returns its tcp:// address."""
    procs = []

    def start(profile: str) -> str:
        proc, port = serve(profile)
        procs.append(proc)
        return port

    yield start
    for proc in procs:
        end(proc)
