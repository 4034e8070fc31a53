"""Fixtures of the motion tests: `servotool sim serve` on a free loopback port, for a second process to use."""

from __future__ import annotations

import os
import re
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
        env=dict(os.environ),
    )
    line = proc.stderr.readline()
    m = re.search(r"(tcp://127\.0\.0\.1:\d+)", line)
    assert m, line
    return proc, m.group(1)


@pytest.fixture
def served(sim_dir):
    """`servotool sim serve` (DSX7E) on a free loopback port; yields its tcp:// address."""
    proc, port = serve("dsx7e")
    yield port
    proc.terminate()
    proc.wait(timeout=10)


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
        proc.terminate()
        proc.wait(timeout=10)
