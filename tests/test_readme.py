"""The README's transcripts are what the code prints: man/transcripts.py replays every one on a fresh simulated drive
and compares, numbers masked (identification figures differ from run to run; wording, lines and tables may not)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(os.name == "nt", reason="the transcripts are POSIX shell sessions")
def test_the_readme_transcripts_are_what_the_code_prints():
    done = subprocess.run(
        [sys.executable, str(ROOT / "man" / "transcripts.py"), "--check"],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
