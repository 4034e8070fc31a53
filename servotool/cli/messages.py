"""Wording library errors for the user: the facts an error carries, and the commands that fix it.

Suggested commands repeat the connection options the user gave on the command line (--port, --profile,
--unit, ...), so that copying one reaches the same drive.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import fields

from servotool.config import ConnectOptions
from servotool.errors import ServoError, SetupGap, SetupRequired
from servotool.ops.restore import RestoreFailed

# ConnectOptions field -> its long option on the command line
OPTION_FLAGS = {"port": "--port", "baud": "--baud", "parity": "--parity", "stopbits": "--stopbits",
                "unit": "--unit", "timeout": "--timeout", "retries": "--retries", "profile": "--profile"}


def connection_args(given: ConnectOptions) -> list[str]:
    """The connection options the user gave, as arguments to put before a suggested sub-command."""
    args: list[str] = []
    for f in fields(ConnectOptions):
        value = getattr(given, f.name)
        if value is not None:
            args += [OPTION_FLAGS[f.name], f"{value:g}" if isinstance(value, float) else str(value)]
    return args


def command(given: ConnectOptions, *args: str) -> str:
    """A servotool command line the user can copy: 'servotool [connection options] ARGS'."""
    return shlex.join(["servotool", *connection_args(given), *args])


def error_text(exc: ServoError, given: ConnectOptions) -> str:
    """The one line to show for a library error."""
    if isinstance(exc, SetupRequired):
        return setup_text(exc, given)
    if isinstance(exc, RestoreFailed):
        return restore_failed_text(exc, given)
    return str(exc)


def setup_text(exc: SetupRequired, given: ConnectOptions) -> str:
    """The refusal, then how to fix it: set the values (stored, and a power cycle, for those that need one)."""
    def set_command(gaps: Sequence[SetupGap], save: bool) -> str:
        return command(given, "param", "set", *(["--save"] if save else []), *(a for g in gaps for a in g.assignments))

    text, count = str(exc), len(exc.settings())
    later = [g for g in exc.missing if g.power_cycle]
    now = [g for g in exc.missing if not g.power_cycle]
    if not later and not exc.waiting:
        return text + f" — set {'it' if count == 1 else 'them'} with '{set_command(now, False)}'"
    cycle = "power-cycle the drive"
    if exc.waiting:
        cycle += f" ('{command(given, 'sim', 'reset', '--power-cycle')}' on the simulator)"
    if later:
        codes = ", ".join(g.code for g in later)
        text += (f" — set {'it' if len(later) == 1 else 'them'} with '{set_command(later, exc.save)}', {cycle} "
                 f"({codes} take{'s' if len(later) == 1 else ''} effect after a power cycle)")
    else:
        text += f" — {cycle}"
    if now:
        text += f", then '{set_command(now, False)}'"
    return text


def restore_failed_text(exc: RestoreFailed, given: ConnectOptions) -> str:
    """Where a restore stopped and the drive's state, then what to do with the automatic backup."""
    auto, text = str(exc.auto_backup), exc.facts()
    if exc.next_step == "compare":
        return text + (f": when it does, compare it with '{command(given, 'param', 'diff', auto)}' and restore "
                       f"that file if needed")
    if exc.next_step == "restore":
        return text + f"; run '{command(given, 'param', 'restore', auto)}' once the cause is fixed"
    if exc.source is not None:
        return text + f"; run '{command(given, 'param', 'restore', str(exc.source), '--yes')}' again once the cause " \
            f"is fixed"
    return text
