"""The CLI starts where POSIX terminal modules do not exist (Windows): they are imported only when used."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
POSIX_ONLY = ("termios", "tty", "fcntl")

# A None entry in sys.modules makes `import name` raise ImportError, as on a platform without the module.
PROBE = f"""
import sys
for name in {POSIX_ONLY!r}:
    sys.modules[name] = None
import servotool.cli.jog
from servotool.cli.main import run
sys.argv = ["servotool", *sys.argv[1:]]
run()
"""


def start(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", PROBE, *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
        env={**os.environ, "COLUMNS": "200"},
    )


def test_help_works_without_termios_tty_and_fcntl():
    for args in (("--help",), ("jog", "--help"), ("sim", "--help")):
        r = start(*args)
        assert r.returncode == 0, r.stderr
        assert "Usage" in r.stdout, r.stdout


def test_the_probe_really_hides_the_modules():
    r = subprocess.run(
        [sys.executable, "-c", PROBE.replace("import servotool.cli.jog", "import termios")],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=60,
    )
    assert r.returncode != 0 and "termios" in r.stderr
