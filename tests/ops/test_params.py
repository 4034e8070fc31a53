"""param set across processes: read-modify-write under the port's lock (issue 30 item 3)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from tests.ops.plain_client import read_registers

ROOT = Path(__file__).resolve().parents[2]


def test_two_processes_setting_different_fields_of_one_register_both_land(serve):
    """`param set Po018.A=1` beside `param set Po018.B=1`: each reads the register and writes it whole, so a read
    outside the lock lost one field in 9 of 10 rounds. A reply delay widens the window between read and write."""
    port = serve("sd25", "--response-delay", "30")
    address = 18  # Po018, fields A (bits 0-3) and B (bits 4-7)

    def servotool(*args: str) -> subprocess.Popen[str]:
        return subprocess.Popen(
            [sys.executable, "-m", "servotool", "--port", port, "-P", "sd25", *args],
            cwd=ROOT,
            env=dict(os.environ),
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )

    for _round in range(3):
        reset = servotool("param", "set", "Po018=0")
        assert reset.wait(60) == 0
        assert read_registers(port, address) == [0]
        both = [servotool("param", "set", "Po018.A=1"), servotool("param", "set", "Po018.B=1")]
        for proc in both:
            assert proc.wait(60) == 0, proc.stderr.read() if proc.stderr else ""
        assert read_registers(port, address) == [0x11]
