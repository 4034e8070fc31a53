"""Fixtures of the ops tests: `servotool sim serve` on a free loopback port."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def serve(sim_dir) -> Iterator[Callable[..., str]]:
    """Start `servotool sim serve --profile P [ARGS]` on a free loopback port; returns its tcp:// address."""
    procs: list[subprocess.Popen[str]] = []

    def start(profile: str, *args: str) -> str:
        proc = subprocess.Popen(
            [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0", "-P", profile, *args],
            cwd=ROOT,
            stderr=subprocess.PIPE,
            text=True,
            env=dict(os.environ),
        )
        procs.append(proc)
        line = proc.stderr.readline() if proc.stderr else ""
        m = re.search(r"(tcp://127\.0\.0\.1:\d+)", line)
        assert m, line
        return m.group(1)

    yield start
    for proc in procs:
        proc.terminate()
        proc.wait(timeout=10)
