"""Output helpers shared by the commands: rich tables on stdout, messages on stderr, JSON."""

from __future__ import annotations

import json
import sys
from typing import Any

from rich.console import Console
from rich.table import Table

# Piped output must not wrap at rich's 80-column default: scripts grep it.
out = Console(highlight=False, width=None if sys.stdout.isatty() else 200)
err = Console(stderr=True, highlight=False, soft_wrap=True)


class Verbosity:
    """Global -q/-v state."""

    level = 0  # -1 quiet, 0 normal, 1+ verbose


def info(text: str) -> None:
    """A progress/status line on stderr (suppressed by --quiet)."""
    if Verbosity.level >= 0:
        err.print(text, markup=False)


def notice(text: str) -> None:
    """A line on stderr that --quiet does not hide (that the drive is simulated, for one)."""
    err.print(text, markup=False)


def warn(text: str) -> None:
    err.print(f"servotool: warning: {text}", markup=False)


def emit_json(data: Any) -> None:
    sys.stdout.write(json.dumps(data, indent=2, ensure_ascii=False, default=str) + "\n")
    sys.stdout.flush()


def table(*columns: str, title: str | None = None) -> Table:
    t = Table(title=title, show_lines=False, header_style="bold", title_justify="left")
    for c in columns:
        justify = "right" if c in ("Value", "Default", "Min", "Max", "Address") else "left"
        t.add_column(c, justify=justify, overflow="fold")
    return t


def trace_frame(sending: bool, data: bytes) -> None:
    """-v: every RTU frame in hex."""
    err.print(f"{'>>' if sending else '<<'} {data.hex(' ')}", markup=False, style="dim")
