"""`servotool shell`: one port opened once, the command line's own commands typed at a prompt.

Each line runs through the same app as a command line (cli.main.dispatch), with the drive the shell opened
(cli.common.drive reuses its Bus): one identity check, the embedded simulator started once. prompt_toolkit gives the
history, the completion (click's own completers: sub-commands, options, codes) and a status line that a background
thread refreshes while the prompt waits; it never reads while a command runs, so the RS485 line keeps one master.
"""

from __future__ import annotations

import os
import shlex
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import Any

import typer

from servotool.cli.common import State, notice_for, resolved, state
from servotool.cli.render import Verbosity, err, info, trace_frame
from servotool.connection import PARITIES, ConnectOptions, Resolved, check_unit, effective, merge
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.session import Bus

PROMPT = "servotool> "
STATUS_EVERY_S = 1.0
FIXED = ("echo", "turnaround_ms", "silence_ms")  # line habits the open link was made with


class ShellBus(Bus):
    """The shell's open port, with the options it was opened from (a line's global options are checked against
    them) and the switch that lets frames be shown (-v) only while a typed command runs."""

    def __init__(self, resolved: Resolved, options: ConnectOptions, notice: Callable[[str], None]) -> None:
        self.options = options
        self.commanding = False
        super().__init__(resolved, trace=self._trace, notice=notice)

    def _trace(self, sending: bool, data: bytes) -> None:
        if self.commanding and Verbosity.level > 0:
            trace_frame(sending, data)


def shell(ctx: typer.Context) -> None:
    """Type commands on one open port: the same commands and options as the command line, without reopening the
    port or checking the drive again; history, Tab completion of commands, options and codes, a status line (speed,
    servo, alarm). Ctrl-C stops what runs (a JOG stops the motor) and keeps the shell; Ctrl-D or 'exit' leaves."""
    if state(ctx).bus is not None:
        raise UsageError("already in the shell")
    res = resolved(ctx)
    bus = ShellBus(res, state(ctx).options, notice_for(ctx))
    try:
        [drive] = bus.drives()  # the identity check and the journal's recovery, once
        terminal = sys.stdin.isatty() and sys.stdout.isatty()
        status = _interactive(bus, drive) if terminal else _scripted(bus)
    finally:
        bus.close()
    if status:
        raise typer.Exit(status)


def line_options(bus: ShellBus, given: ConnectOptions) -> tuple[ConnectOptions, Resolved]:
    """A typed line's global options over the shell's: the same port and line, or UsageError; a unit of its own
    (checked against its profile the first time it is used)."""
    in_force = _in_force(bus)
    for name, value in vars(given).items():
        if value is None or name in ("unit", "travel"):
            continue
        if name in FIXED or _normal(name, value) != in_force.get(name):
            flag = "--" + name.replace("_", "-")
            raise UsageError(
                f"{flag} {value}: the shell keeps {in_force['port']} open as it was started; "
                f"leave it (Ctrl-D) and start it with the options wanted"
            )
    res = bus.resolved if given.unit is None else replace(bus.resolved, unit=check_unit(given.unit))
    # the profile in force, found or given, as if given on the line (a plan's own yields to it, as to -P)
    return merge(given, bus.options, ConnectOptions(profile=res.profile.id)), res


def _in_force(bus: Bus) -> dict[str, Any]:
    s, res = bus.resolved.settings, bus.resolved
    profile = effective(bus.options).profile or res.profile.id
    return {
        "port": s.port,
        "baud": s.line.baud,
        "parity": s.line.parity,
        "stopbits": s.line.stopbits,
        "profile": profile,
        "timeout": s.timeout,
        "retries": s.retries,
        "no_identity_check": not res.identity_check,
    }


def _normal(name: str, value: Any) -> Any:
    if name == "parity":
        return PARITIES.get(str(value).upper(), value)
    if name == "timeout":
        return float(value)
    return value


# ----- running lines -----------------------------------------------------------------------------------------------


def run_line(bus: ShellBus, line: str) -> int | None:
    """One typed line through the app; its exit status, None for nothing to run; EOFError for 'exit'."""
    from servotool.cli.main import dispatch

    try:
        words = shlex.split(line, posix=os.name != "nt")
    except ValueError as exc:
        err.print(f"servotool: error: {str(exc).lower()} in: {line.strip()}", markup=False)
        return 2
    if words[:1] == ["servotool"]:
        words = words[1:]
    if not words:
        return None
    if words[0] in ("exit", "quit"):
        raise EOFError
    if words[0] == "help":
        words = [*words[1:], "--help"]
    bus.commanding = True
    try:
        return dispatch(words, State(bus=bus, line_options=lambda given: line_options(bus, given)))
    except SystemExit as exc:  # a command that exits the interpreter's way (help, completion install)
        return exc.code if isinstance(exc.code, int) else 1
    finally:
        bus.commanding = False


def _scripted(bus: ShellBus) -> int:
    """Lines from a pipe or a file: each run in turn; the status of the last."""
    status = 0
    for line in sys.stdin:
        try:
            done = run_line(bus, line)
        except EOFError:
            break
        status = status if done is None else done
    return status


def _interactive(bus: ShellBus, drive: Drive) -> int:
    from prompt_toolkit import PromptSession
    from prompt_toolkit.history import FileHistory, InMemoryHistory

    from servotool.cli.shell_complete import CommandCompleter
    from servotool.files import shell_history_file

    path = shell_history_file()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        history: Any = FileHistory(str(path))
    except OSError as exc:
        info(f"servotool: history not kept ({path}: {exc.strerror})")
        history = InMemoryHistory()
    status_line = StatusLine(lambda: status_text(drive))
    session: Any = PromptSession(
        history=history,
        completer=CommandCompleter(_profile_args(bus)),
        complete_while_typing=False,
        bottom_toolbar=lambda: status_line.text,
        refresh_interval=0.5,
    )
    info("servotool: shell: the command line's commands; Tab completes, Ctrl-C stops, Ctrl-D leaves")
    status_line.start()
    try:
        with _leave_on_termination() as leaving:
            while not leaving.is_set():
                with status_line.reading():
                    try:
                        line = session.prompt(PROMPT)
                    except KeyboardInterrupt:
                        continue
                    except EOFError:
                        break
                try:
                    run_line(bus, line)
                except EOFError:
                    break
                except KeyboardInterrupt:  # between a command's end and the next prompt
                    continue
    finally:
        status_line.close()
    return 0


def _profile_args(bus: Bus) -> list[str]:
    """The root options that tell code completers which profile is open."""
    return ["--profile", effective(bus.options).profile or bus.resolved.profile.id]


@contextmanager
def _leave_on_termination() -> Iterator[threading.Event]:
    """A terminate or hang-up signal ends the shell, not only the command it interrupts (which unwinds as at
    Ctrl-C, putting back what it changed on the drive)."""
    leaving = threading.Event()
    names = [n for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
    before = {n: signal.getsignal(getattr(signal, n)) for n in names}

    def terminated(_signum: int, _frame: object) -> None:
        leaving.set()
        raise KeyboardInterrupt

    for n in names:
        signal.signal(getattr(signal, n), terminated)
    try:
        yield leaving
    finally:
        for n, handler in before.items():
            signal.signal(getattr(signal, n), handler)


# ----- the status line ---------------------------------------------------------------------------------------------


def status_text(drive: Drive) -> str:
    """'dsx7e unit 1 │ speed 0 rpm │ servo off │ no alarm'."""
    from servotool.ops.status import glance

    now = glance(drive)
    parts = [f"{drive.profile.id} unit {drive.unit}"]
    if now.speed is not None:
        parts.append(f"speed {now.speed.text} {now.speed.entry.unit or ''}".rstrip())
    if now.servo_on is not None:
        parts.append("servo ON" if now.servo_on else "servo off")
    if now.alarm is not None:
        parts.append(f"ALARM {now.alarm.display} {now.alarm.name}" if now.alarm.active else "no alarm")
    return " │ ".join(parts)


class StatusLine:
    """A line of text read from the drive by a background thread, only while `reading()` holds (the prompt
    waits): when it ends, a read under way is waited for, so a command has the line to itself."""

    def __init__(self, read: Callable[[], str], every_s: float = STATUS_EVERY_S) -> None:
        self.read, self.every_s = read, every_s
        self.text = "reading the drive ..."
        self._line = threading.Lock()  # held by a status read, or by the shell while a command runs
        self._idle = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="servotool-shell-status", daemon=True)
        self._line.acquire()

    def start(self) -> None:
        self._thread.start()

    @contextmanager
    def reading(self) -> Iterator[None]:
        """While the prompt waits: the status line may use the link."""
        self._idle.set()
        self._line.release()
        try:
            yield
        finally:
            self._idle.clear()
            self._line.acquire()  # after the read under way, if any

    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._idle.wait(0.2) or not self._line.acquire(timeout=0.2):
                continue
            try:
                if not self._idle.is_set() or self._stop.is_set():
                    continue
                self.text = self._read()
            finally:
                self._line.release()
            self._stop.wait(self.every_s)

    def _read(self) -> str:
        try:
            return self.read()
        except ServoError as exc:
            return f"status: {str(exc).splitlines()[0]}"
        except Exception as exc:  # a bug must not end the shell's status line silently
            return f"status: internal error: {type(exc).__name__}: {exc}"

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
