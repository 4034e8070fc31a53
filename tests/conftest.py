"""Shared fixtures: an isolated simulated-drive state dir and a CLI runner that runs the CLI as a user would."""

from __future__ import annotations

import _thread
import faulthandler
import gc
import io
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def pytest_configure(config: pytest.Config) -> None:
    """SIGINT handled in the test process, so that every servotool child it starts has the default again: a suite
    started in the background of a non-interactive shell (`nohup pytest &`) inherits SIGINT ignored and passes that
    on, and then the Ctrl-C tests' signal is lost and each served drive's stop waits out its 30 s (seen: a run stuck
    in sim_serve's teardown, its children with SigIgn bit 2 set)."""
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def _children_keep_their_bytecode() -> None:
    """Where the runner sets PYTHONDONTWRITEBYTECODE, every `python -m servotool` the tests start (about a
    thousand) would compile servotool's modules from source again: a quarter of a `param get`'s CPU time, which
    an installed package, its .pyc files written by pip, never spends. The children (and pytest-xdist's workers)
    keep their bytecode in the pytest cache folder instead, outside the source tree, as bench/startup.py does."""
    if os.environ.get("PYTHONDONTWRITEBYTECODE") and not os.environ.get("PYTHONPYCACHEPREFIX"):
        del os.environ["PYTHONDONTWRITEBYTECODE"]
        os.environ["PYTHONPYCACHEPREFIX"] = str(ROOT / ".pytest_cache" / "pycache")


_children_keep_their_bytecode()


@dataclass
class Result:
    code: int
    out: str
    err: str

    def json(self):
        return json.loads(self.out)


@pytest.fixture(autouse=True)
def _no_terminal_size_from_the_runner(monkeypatch) -> None:
    """Output is judged as a pipe gives it: not wrapped, unless a test gives its own COLUMNS. The runner's
    COLUMNS and LINES are not the test's: pytest imports readline, whose GNU library puts LINES=24 COLUMNS=80
    in the process environment (below os.environ) without a terminal, so a child started without env= gets them,
    and pytest-xdist's workers start with them in os.environ (as with a developer's exported COLUMNS)."""
    for name in ("COLUMNS", "LINES"):
        monkeypatch.delenv(name, raising=False)
        os.unsetenv(name)


@pytest.fixture
def sim_dir(tmp_path, monkeypatch) -> Path:
    """Each test gets its own simulated drives (state files), automatic-backup folder and no user config; its
    simulated drives answer without the wire time of their line (SERVOTOOL_SIM_LINE_BAUD=fast) unless their
    `sim config --line-baud` names one; the `factory_line` fixture gives them the default, their factory line."""
    d = tmp_path / "sim"
    monkeypatch.setenv("SERVOTOOL_SIM_DIR", str(d))
    monkeypatch.setenv("SERVOTOOL_BACKUP_DIR", str(tmp_path / "auto-backups"))
    monkeypatch.setenv("SERVOTOOL_CONFIG", str(tmp_path / "no-config.yaml"))
    monkeypatch.setenv("SERVOTOOL_SIM_LINE_BAUD", "fast")
    for var in ("SERVOTOOL_PORT", "SERVOTOOL_PROFILE", "SERVOTOOL_UNIT", "SERVOTOOL_BAUD"):
        monkeypatch.delenv(var, raising=False)
    return d


@pytest.fixture
def factory_line(sim_dir, monkeypatch) -> Path:
    """sim_dir with the simulator as a user gets it: each drive's line emulated unless its sim config says
    otherwise."""
    monkeypatch.delenv("SERVOTOOL_SIM_LINE_BAUD", raising=False)
    return sim_dir


def _in_process(args: tuple[str, ...], input: str | None, env: dict[str, str], timeout: float) -> Result:
    """One command line through the CLI's own dispatch (what `servotool shell` runs for each line it reads), in this
    process: its environment, working directory, stdin and stdout/stderr as a piped child's, the output consoles
    made anew. A child costs ~0.18 s of CPU to start (interpreter, imports, profile), a thousand times a run. A
    command still running after `timeout` is interrupted as a Ctrl-C would (its stop sequence runs) and the test
    fails with every thread's stack at that moment, as a child's timeout failed it: a hang is not left to the CI's
    own limit, with nothing said of where it waited."""
    from servotool.cli import render
    from servotool.cli.common import State
    from servotool.cli.main import dispatch

    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    saved_streams, saved_argv = (sys.stdin, sys.stdout, sys.stderr), sys.argv
    out, err = _PipedText(), _PipedText()
    os.environ.clear()
    os.environ.update(env)
    os.chdir(ROOT)
    sys.stdin, sys.stdout, sys.stderr = io.StringIO(input or ""), out, err
    sys.argv = [str(ROOT / "servotool" / "__main__.py"), *args]  # as `python -m servotool` sets it (the change log's)
    render.out._console = render.err._console = None
    deadline = _Deadline(timeout)
    threads = set(threading.enumerate())
    gc.freeze()  # the test process's heap (every test's objects) is no collection's to walk during a real-time motion
    try:
        try:
            code = dispatch(list(args), State())
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    finally:
        deadline.cancel()
        gc.unfreeze()
        render.out._console = render.err._console = None
        sys.stdin, sys.stdout, sys.stderr = saved_streams
        sys.argv = saved_argv
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
    _no_thread_left(threads, args)
    if deadline.stacks is not None:
        pytest.fail(f"servotool {' '.join(args)} still ran after {timeout} s; its threads then:\n{deadline.stacks}")
    return Result(code, out.getvalue(), err.getvalue())


class _Deadline:
    """After `timeout` s: every thread's stack kept, then the main thread interrupted (a KeyboardInterrupt, as a
    user's Ctrl-C), unless cancelled first."""

    def __init__(self, timeout: float) -> None:
        self.stacks: str | None = None
        self._timer = threading.Timer(timeout, self._expire)
        self._timer.daemon = True
        self._timer.start()

    def _expire(self) -> None:
        with tempfile.TemporaryFile("w+") as dump:
            faulthandler.dump_traceback(dump, all_threads=True)
            dump.seek(0)
            self.stacks = dump.read()
        _thread.interrupt_main()

    def cancel(self) -> None:
        self._timer.cancel()
        self._timer.join()


def _no_thread_left(before: set[threading.Thread], args: tuple[str, ...]) -> None:
    """A command ends its threads (a child's exit would wait for one, or cut a daemon short): one still running
    here would go on in the test process, unseen."""
    left = [t for t in threading.enumerate() if t not in before]
    for thread in left:
        thread.join(timeout=5)
    assert not [t for t in left if t.is_alive()], f"servotool {' '.join(args)} left threads running: {left}"


class _PipedText(io.StringIO):
    """A text stream as a child's piped stdout or stderr looks from inside: UTF-8, not a terminal, no descriptor."""

    encoding = "utf-8"


def _child(args: tuple[str, ...], input: str | None, env: dict[str, str], timeout: float) -> Result:
    proc = subprocess.run(
        [sys.executable, "-m", "servotool", *args],
        capture_output=True,
        text=True,
        input=input,
        env=env,
        timeout=timeout,
        cwd=ROOT,
    )
    return Result(proc.returncode, proc.stdout, proc.stderr)


@pytest.fixture
def cli(sim_dir):
    """Run `servotool ARGS` as a user would, on a screen wide enough that nothing wraps (stdout and stderr are
    wrapped to COLUMNS; tests of the width give their own); returns exit code, stdout, stderr. In this process
    through the CLI's dispatch, as `servotool shell` runs a line (SERVOTOOL_TEST_CLI=process: each in a child);
    `cli_process` runs each as `python -m servotool ARGS`, for what only a process shows (the entry point, signals,
    the interpreter's exit, a timeout)."""

    def run(*args: str, input: str | None = None, env: dict[str, str] | None = None, timeout: float = 120) -> Result:
        full_env = {**os.environ, "COLUMNS": "1000", **(env or {})}
        if os.environ.get("SERVOTOOL_TEST_CLI") == "process":
            return _child(args, input, full_env, timeout)
        return _in_process(args, input, full_env, timeout)

    return run


@pytest.fixture
def cli_process(sim_dir):
    """`python -m servotool ARGS` in a child process, as `cli` is called."""

    def run(*args: str, input: str | None = None, env: dict[str, str] | None = None, timeout: float = 120) -> Result:
        return _child(args, input, {**os.environ, "COLUMNS": "1000", **(env or {})}, timeout)

    return run


@pytest.fixture
def sim_serve(sim_dir):
    """Start `servotool sim serve --port tcp://127.0.0.1:0 ARGS` in its own process; returns its tcp:// port. Each
    one is stopped (Ctrl-C) at the end of the test."""
    procs: list[subprocess.Popen] = []

    def start(*args: str) -> str:
        proc = subprocess.Popen(
            [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0", *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
        )
        procs.append(proc)
        banner = proc.stderr.readline()
        assert "serving on tcp://" in banner, banner
        return banner.split("serving on ")[1].split()[0]

    yield start
    for proc in procs:
        proc.send_signal(signal.SIGINT)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()


@dataclass
class VirtualPlan:
    """A plan's runner in-process on virtual time, over one simulated drive (unit 1) with its machine behind it;
    `safety` collects the runner's safety lines."""

    runner: object  # servotool.commission.runner.Runner
    sim: object  # servotool.sim.device.SimulatedDrive
    clock: object  # servotool.clock.VirtualClock
    safety: list[str]


@pytest.fixture
def virtual_plan(tmp_path, sim_dir):
    """build(steps, profile_id="dsx7e", **machine): the plan `profile: ID` with these step lines, run by the plan
    runner in-process on virtual time, the profile's motion setup made on the drive and its machine set (sim
    config's names), its line at 115200 baud; nothing asks and nothing is logged."""
    from servotool.clock import VirtualClock
    from servotool.commission.plan import load_plan
    from servotool.commission.runner import Runner
    from servotool.drive import Drive
    from servotool.model.loader import load_profile
    from servotool.sim.firmware import build_drive
    from servotool.sim.virtual import VirtualLink, make_motion_setup

    def build(steps: str, profile_id: str = "dsx7e", **machine: float) -> VirtualPlan:
        plan_file = tmp_path / "plan.yaml"
        plan_file.write_text(f"profile: {profile_id}\nsteps:\n{steps}")
        clock = VirtualClock(100.0)
        profile = load_profile(profile_id)
        sim = build_drive(profile, 1, clock, persist=False)
        make_motion_setup(sim)
        sim.settings.update(machine)
        sim.firmware.reconfigure()
        drive = Drive(VirtualLink([sim], clock, 115200), profile, 1)
        safety: list[str] = []
        runner = Runner(
            load_plan(plan_file),
            [drive],
            yes=True,
            continue_on_error=False,
            ask=lambda _unit, _question: True,
            log=lambda _line: None,
            clock=clock,
            safety=safety.append,
        )
        return VirtualPlan(runner, sim, clock, safety)

    return build
