"""Examples: every sub-command's help shows one or two, and every example of the man page runs, in order, against
the simulator (after the README's motion set-up), ending as it says."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import typer

from servotool.cli.examples import EXAMPLES, for_command
from servotool.cli.main import app

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "man" / "servotool.1"
WIDTH = 80


def leaves(group, prefix=""):
    for name in group.list_commands(None):
        cmd = group.get_command(None, name)
        path = f"{prefix} {name}".strip()
        if hasattr(cmd, "commands"):
            yield from leaves(cmd, path)
        else:
            yield path, cmd


@pytest.fixture(scope="module")
def commands():
    return dict(leaves(typer.main.get_command(app)))


def test_every_sub_command_has_one_or_two_examples_of_itself(commands):
    counts = {path: len(for_command(path)) for path in commands}
    assert all(1 <= n <= 2 for n in counts.values()), {p: n for p, n in counts.items() if not 1 <= n <= 2}
    for path, line, _ in EXAMPLES:
        assert path in commands, f"example of no command: {path}"
        first = line.split(" & ")[0].split()
        words = [w for w in first if not w.startswith("-")]
        assert " ".join(words).find(path) >= 0, f"{line!r} does not run {path!r}"


def test_help_shows_the_examples_within_80_columns_and_no_type_on_flags(commands):
    for path, cmd in commands.items():
        text = cmd.get_help(typer.Context(cmd, info_name=f"servotool {path}", terminal_width=WIDTH))
        assert "<bool>" not in text and "BOOLEAN" not in text, (path, text)
        assert "Examples:" in text, path
        for line, what in for_command(path):
            for part in line.split(" & "):
                assert part.strip(" &") in text, (path, part)
            assert what in text
        assert all(len(row) <= WIDTH for row in text.splitlines()), (
            path,
            [r for r in text.splitlines() if len(r) > 80],
        )


def test_every_command_has_its_one_line_help_in_the_registry():
    from servotool.cli.main import COMMANDS

    missing = [name for name, spec in COMMANDS.items() if not spec.help]
    assert not missing, f"give lazy(..., help=...) in cli/main.py: {missing}"
    assert all(len(f"  {name:10}{spec.help}") <= WIDTH for name, spec in COMMANDS.items())


def test_root_help_lists_every_command_without_loading_one(cli):
    r = cli("--help")
    assert r.code == 0 and "Usage:" in r.out and "<bool>" not in r.out
    listed = r.out[r.out.index("Commands:") :]
    for name in ("param", "jog", "tune", "sim", "trace", "plot"):
        assert re.search(rf"^  {name}\s+\S", listed, re.M), name


def _page_examples() -> list[tuple[str, str]]:
    """(command line, what it does) of each example in the man page's EXAMPLES section."""
    text = PAGE.read_text()
    section = text[text.index(".SH EXAMPLES") : text.index(".SH SEE ALSO")].splitlines()
    plain = lambda roff: re.sub(r"\\f[BIRP]|\\&", "", roff).replace("\\-", "-").replace("\\e", "\\")  # noqa: E731
    return [(plain(section[i + 1]), plain(section[i + 2])) for i, row in enumerate(section) if row == ".TP"]


def test_the_man_page_shows_every_example():
    assert _page_examples() == [(line, what) for _, line, what in EXAMPLES]


def _readme_setup() -> list[str]:
    """The commands of the README's block that sets the simulated drives up for motion."""
    text = (ROOT / "README.md").read_text()
    block = text[text.index("```sh", text.index("set them up first")) + 5 :]
    block = block[: block.index("```")].replace("\\\n", " ")
    return [row.split("#")[0].strip() for row in block.splitlines() if row.strip().startswith("servotool ")]


def _documented_exit(what: str) -> int:
    found = re.search(r"\(exit (\d+)\)\.$", what)
    return int(found.group(1)) if found else 0


def _wait_for(path: Path) -> None:
    end = time.monotonic() + 10
    while not path.exists():
        assert time.monotonic() < end, path
        time.sleep(0.05)


@pytest.mark.skipif(os.name == "nt" or not shutil.which("socat"), reason="needs a POSIX shell and socat")
def test_every_man_page_example_runs_against_the_simulator(sim_dir, tmp_path):
    bin_dir, work = tmp_path / "bin", tmp_path / "work"
    bin_dir.mkdir()
    (bin_dir / "servotool").write_text(f'#!/bin/sh\nexec "{sys.executable}" -m servotool "$@"\n')
    (bin_dir / "servotool").chmod(0o755)
    shutil.copytree(ROOT / "examples", work / "examples")
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}", "COLUMNS": "80"}
    # /dev/ttyUSB0 of the examples: a socat pty with a simulated SD25 (its own state) on the other end
    drive_end, port = tmp_path / "drive", tmp_path / "ttyUSB0"
    socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={drive_end}", f"pty,raw,echo=0,link={port}"])
    _wait_for(drive_end)
    _wait_for(port)
    serve = [sys.executable, "-m", "servotool", "sim", "serve", "-P", "sd25", "--port", str(drive_end)]
    wire = subprocess.Popen(
        serve, env={**env, "SERVOTOOL_SIM_DIR": str(tmp_path / "wire")}, stderr=subprocess.PIPE, text=True
    )
    tcp = "tcp://127.0.0.1:0"  # the system's free port when it binds (one found before could be taken meanwhile)
    try:
        assert "serving on" in wire.stderr.readline()
        for line in _readme_setup():
            r = subprocess.run(["sh", "-c", line], cwd=work, env=env, capture_output=True, text=True, timeout=120)
            assert r.returncode == 0, (line, r.stderr)
        failed = []
        for line, what in _page_examples():
            line = line.replace("/dev/ttyUSB0", str(port)).replace("tcp://127.0.0.1:5020", tcp)
            t0 = time.monotonic()
            status, err = _run(line, "Ctrl-C" in what, work, env)
            print(f"{time.monotonic() - t0:5.1f} s  exit {status}  {line}")
            if status != _documented_exit(what):
                failed.append((line, status, err[-600:]))
        assert not failed, failed
        assert (work / "tune-report").is_dir() and (work / "start.png").is_file() and (work / "stop.csv").is_file()
    finally:
        for proc in (wire, socat):
            proc.terminate()
            proc.wait(timeout=10)


def _run(line: str, until_ctrl_c: bool, cwd: Path, env: dict[str, str]) -> tuple[int, str]:
    """Run one example in a shell of its own (its whole process group ended after); Ctrl-C once it serves."""
    shell = ["sh", "-c", f"exec {line}" if until_ctrl_c else line]
    proc = subprocess.Popen(
        shell, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        if until_ctrl_c:  # the shell replaced by the command, which alone gets the signal
            while "serving on" not in (said := proc.stderr.readline()):
                assert said, "ended before it served"
            os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=240)
        return proc.returncode, err
    finally:  # a command left in the background (`A & B` where B failed) goes too
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
