"""servotool on Windows: the main commands run with termios, tty and fcntl unimportable and sys.platform 'win32'.

A sitecustomize on PYTHONPATH plays Windows: the third-party and standard modules that choose their platform
implementation when imported are loaded for the real platform first (they have their own Windows support), then
the POSIX-only modules are blocked and sys.platform says win32, so what is tested is servotool's own code.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from servotool.cli import keys

ROOT = Path(__file__).resolve().parents[2]

SITECUSTOMIZE = textwrap.dedent("""
    import importlib.abc
    import sys
    import sysconfig

    import asyncio, selectors, socket, subprocess  # noqa: E401
    import filelock, platformdirs, pymodbus.client, rich.console, serial, typer, yaml  # noqa: E401

    sysconfig.get_config_vars()
    BLOCKED = ("termios", "tty", "fcntl")


    class NotOnWindows(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r} (as on Windows)", name=name)
            return None


    sys.meta_path.insert(0, NotOnWindows())
    for name in BLOCKED:
        sys.modules.pop(name, None)
    sys.platform = "win32"
""")

PLAN = """\
port: sim
profile: dsx7e
steps:
  - set: {Pn101: 25.0}
  - backup: axis-{unit}.yaml
"""


@pytest.fixture
def windows(tmp_path, sim_dir):
    site = tmp_path / "site"
    site.mkdir()
    (site / "sitecustomize.py").write_text(SITECUSTOMIZE)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), str(ROOT)]), "COLUMNS": "100"}

    def run(*args: str, code: str | None = None) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "-c", code] if code else [sys.executable, "-m", "servotool", *args]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)

    return run


def test_the_fake_windows_blocks_the_posix_modules(windows):
    r = windows(code="import sys; print(sys.platform); import termios")
    assert r.stdout.strip() == "win32"
    assert "No module named 'termios'" in r.stderr


@pytest.mark.parametrize(
    "args",
    [
        ("--help",),
        ("--port", "sim", "param", "get", "Pn004"),
        ("--port", "sim", "param", "set", "Pn101=20"),
        ("--port", "sim", "param", "backup", "-o", "b.yaml"),
        ("--port", "sim", "monitor", "--once", "Un000"),
        ("--port", "sim", "jog", "--speed", "100", "--time", "0.2"),
    ],
)
def test_main_commands_run_on_windows(windows, args):
    r = windows(*args)
    assert r.returncode == 0, r.stderr
    assert "error" not in r.stderr


def test_a_plan_runs_on_windows(windows, tmp_path):
    (tmp_path / "plan.yaml").write_text(PLAN)
    r = windows("run", "plan.yaml", "--yes")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "axis-1.yaml").exists()


@contextmanager
def fake_msvcrt(monkeypatch: pytest.MonkeyPatch, typed: str) -> Iterator[None]:
    pending = list(typed)
    module = type(sys)("msvcrt")
    module.kbhit = lambda: bool(pending)  # type: ignore[attr-defined]
    module.getwch = lambda: pending.pop(0)  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "msvcrt", module)
    monkeypatch.setattr(sys, "platform", "win32")
    yield


def test_windows_keys_arrows_and_letters(monkeypatch):
    for typed, action in (("\xe0M", "fwd"), ("\x00K", "rev"), ("x", ""), (" ", "stop"), ("q", "quit")):
        with fake_msvcrt(monkeypatch, typed), keys.raw_keys() as key:
            assert [key(), key()] == [action, None]
    # a held key queues its repeats: one poll takes them all and answers the last key pressed
    with fake_msvcrt(monkeypatch, "\xe0M\xe0M\xe0Kx"), keys.raw_keys() as key:
        assert [key(), key()] == ["rev", None]
