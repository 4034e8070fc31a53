"""A command in a real terminal for tests: a tmux session on a tmux server of the test's own (its socket in the
test's folder), so that neither a user's tmux nor a stale lock of another server can get in the way."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path


class Terminal:
    """A tmux session running one command, read as the screen shows it."""

    def __init__(self, command: str, folder: Path, width: int = 110, height: int = 30) -> None:
        self.socket = str(folder / "tmux.sock")
        self._tmux("new-session", "-d", "-s", "t", "-x", str(width), "-y", str(height), command)

    def _tmux(self, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        return subprocess.run(["tmux", "-S", self.socket, *args], capture_output=True, text=True, check=check)

    def keys(self, *keys: str, literal: bool = False) -> None:
        self._tmux("send-keys", "-t", "t", *(["-l"] if literal else []), *keys)

    def type(self, text: str) -> None:
        self.keys(text, literal=True)

    def screen(self) -> str:
        return self._tmux("capture-pane", "-p", "-S", "-500", "-t", "t", check=False).stdout

    def wait_for(self, text: str, timeout: float = 30, count: int = 1) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if (screen := self.screen()).count(text) >= count:
                return screen
            time.sleep(0.1)
        raise AssertionError(f"{text!r} (x{count}) not on the screen after {timeout} s:\n{self.screen()}")

    def wait_for_bottom(self, text: str, timeout: float = 30) -> str:
        """The screen once its last non-blank line holds `text` (a status line redrawn after a command's output)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in (bottom := (self.screen().strip().splitlines() or [""])[-1]):
                return bottom
            time.sleep(0.1)
        raise AssertionError(f"{text!r} not on the bottom line after {timeout} s:\n{self.screen()}")

    def close(self) -> None:
        self._tmux("kill-server", check=False)
