"""Wording library errors for the user: the facts an error carries, and the commands that fix it.

Suggested commands repeat the connection options the user gave on the command line (--port, --profile,
--unit, ...), so that copying one reaches the same drive.
"""

from __future__ import annotations

import re
import shlex
from collections.abc import Sequence
from dataclasses import fields
from typing import TYPE_CHECKING

from servotool.connection import ConnectOptions
from servotool.errors import MissingRole, ServoError, SetupGap, SetupRequired, UnknownName
from servotool.words import agree

if TYPE_CHECKING:
    from servotool.ops.restore import RestoreFailed

# Manual references (“L417-419”, “is620p.md L1036”, “(L3215)”): for -v, not for everyone.
_REF = r"(?:[\w./-]+\.md,?\s*)?\bL\d{2,}(?:\s*[-–]\s*L?\d+)?"
MANUAL_REFS = re.compile(rf"\s*\((?:see\s+)?{_REF}(?:\s*[,;]\s*{_REF})*\)|(?:\s*[,;]\s*{_REF})+(?=\))|\s*\b{_REF}")

# ConnectOptions field -> its long option on the command line
OPTION_FLAGS = {
    "port": "--port",
    "baud": "--baud",
    "parity": "--parity",
    "stopbits": "--stopbits",
    "unit": "--unit",
    "timeout": "--timeout",
    "retries": "--retries",
    "profile": "--profile",
    "echo": "--echo",
    "turnaround_ms": "--turnaround-ms",
    "silence_ms": "--silence-ms",
    "no_identity_check": "--no-identity-check",
    "boost": "--boost",
}


def connection_args(given: ConnectOptions) -> list[str]:
    """The connection options the user gave, as arguments to put before a suggested sub-command."""
    args: list[str] = []
    for f in fields(ConnectOptions):
        value = getattr(given, f.name)
        if isinstance(value, bool):
            args += [OPTION_FLAGS[f.name]] if value else (["--no-boost"] if f.name == "boost" else [])
        elif value is not None:
            args += [OPTION_FLAGS[f.name], f"{value:g}" if isinstance(value, float) else str(value)]
    return args


def command(given: ConnectOptions, *args: str) -> str:
    """A servotool command line the user can copy: 'servotool [connection options] ARGS'."""
    return shlex.join(["servotool", *connection_args(given), *args])


def plain(text: str, verbose: bool = False) -> str:
    """Text for the user: manual line references only with -v."""
    return text if verbose else MANUAL_REFS.sub("", text)


def error_code(exc: ServoError) -> str:
    """A stable name for the kind of error (JSON 'code'): UsageError -> usage, SetupRequired -> setup_required."""
    name = re.sub(r"(Error)$", "", type(exc).__name__) or "error"
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def error_text(exc: ServoError, given: ConnectOptions, verbose: bool = False) -> str:
    """The one line to show for a library error: what the user can do; internal names and manual lines with -v."""
    from servotool.ops.restore import RestoreFailed  # the restore module only when a restore failed

    if isinstance(exc, SetupRequired):
        text = setup_text(exc, given)
    elif isinstance(exc, RestoreFailed):
        text = restore_failed_text(exc, given)
    elif isinstance(exc, MissingRole):
        text = missing_role_text(exc, verbose)
    elif isinstance(exc, UnknownName):
        text = unknown_text(exc, given)
    else:
        text = str(exc)
    return with_options(plain(text, verbose), given)


OFFLINE = ("sim", "profiles")  # commands that take no connection options
_SUGGESTED = re.compile(r"'servotool ((?!-)[^']*)'")


def with_options(text: str, given: ConnectOptions) -> str:
    """Commands a library message suggests ('servotool alarm') with the user's connection options, so that
    copying one reaches the same drive; commands that carry options already are left as they are."""

    def repl(m: re.Match[str]) -> str:
        try:
            args = shlex.split(m.group(1))
        except ValueError:
            return m.group(0)
        own = set(OPTION_FLAGS.values()) | {"-p", "-P", "-u", "-b"}
        if not args or args[0] in OFFLINE or own & {a.split("=")[0] for a in args}:
            return m.group(0)  # a command that reaches no drive, or names its own connection
        return "'" + command(given, *args) + "'"

    return _SUGGESTED.sub(repl, text)


def unknown_text(exc: UnknownName, given: ConnectOptions) -> str:
    """An unknown code, group, class or profile, the closest known ones, and where to look it up."""
    if exc.kind == "code":
        return f"{exc} (search with '{command(given, 'param', 'find', exc.name)}')"
    if exc.known:
        kinds = {"class": "classes"}.get(exc.kind, exc.kind + "s")
        return f"{exc} ({kinds}: {', '.join(exc.known)})"
    return str(exc)


# Roles whose name says little to a user.
ROLE_WORDS = {
    "motion_route": "JOG or speed command (a JOG trigger with its speed, or a speed reference with servo-on)",
    "speed_feedback": "motor speed reading",
    "torque_feedback": "motor torque reading",
    "alarm_history_1": "alarm history",
    "alarm_reset": "alarm reset",
    "factory_reset": "factory reset",
    "inertia_id": "inertia identification function",
    "eeprom_save": "command that saves to EEPROM",
    "jog_accel": "JOG ramp setting",
}


def missing_role_text(exc: MissingRole, verbose: bool) -> str:
    """A feature the drive's profile gives no Modbus way to: say so, and what is left to the user."""
    what = ROLE_WORDS.get(exc.role, exc.role.replace("_", " "))
    text = (
        f"{exc.feature}: servotool knows no way to reach the {what} of this drive over Modbus "
        f"(profile {exc.profile_id}); do it on the drive's panel, or give a profile that maps it with --profile"
    )
    return text + (f" [role '{exc.role}']" if verbose else "")


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
        text += (
            f" — set {'it' if len(later) == 1 else 'them'} with '{set_command(later, exc.save)}', {cycle} "
            f"({codes} {agree(len(later), 'takes', 'take')} effect after a power cycle)"
        )
    else:
        text += f" — {cycle}"
    if now:
        text += f", then '{set_command(now, False)}'"
    return text


def restore_failed_text(exc: RestoreFailed, given: ConnectOptions) -> str:
    """Where a restore stopped and the drive's state, then what to do with the automatic backup."""
    auto, text = str(exc.auto_backup), exc.facts()
    if exc.next_step == "compare":
        return text + (
            f": when it does, compare it with '{command(given, 'param', 'diff', auto)}' and restore that file if needed"
        )
    if exc.next_step == "restore":
        return text + f"; run '{command(given, 'param', 'restore', auto)}' once the cause is fixed"
    if exc.source is not None:
        return (
            text + f"; run '{command(given, 'param', 'restore', str(exc.source), '--yes')}' again once the cause "
            f"is fixed"
        )
    return text
