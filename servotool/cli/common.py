"""Glue between typer's context and the library: connection options, opening drives."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import typer

from servotool.cli.render import Verbosity, info, trace_frame, warn
from servotool.config import ConnectOptions, Resolved, resolve
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.session import open_drives


@dataclass
class State:
    options: ConnectOptions = field(default_factory=ConnectOptions)


def state(ctx: typer.Context) -> State:
    root = ctx.find_root()
    if root.obj is None:
        root.obj = State()
    return root.obj


def resolved(ctx: typer.Context) -> Resolved:
    return resolve(state(ctx).options)


@contextmanager
def drive(ctx: typer.Context) -> Iterator[Drive]:
    """The one drive the global options point at; after a command that completed, names each entry the drive
    turned out to lack (once, however often it was asked for)."""
    with open_drives(resolved(ctx), trace=trace_frame if Verbosity.level > 0 else None, notice=info) as drives:
        yield drives[0]
        for e in drives[0].missing.values():
            warn(f"{e.code} ({e.name}): not on this drive (exception 02 for its address); left out")


@contextmanager
def drives(ctx: typer.Context, units: list[int]) -> Iterator[list[Drive]]:
    with open_drives(resolved(ctx), units, trace=trace_frame if Verbosity.level > 0 else None,
                     notice=info) as found:
        yield found


def confirm(question: str, yes: bool) -> bool:
    """Ask before something irreversible; without a terminal, refuse (exit 2) rather than hang."""
    if yes:
        return True
    if not sys.stdin.isatty():
        raise UsageError(f"'{question}' needs confirmation: run in a terminal or pass --yes")
    return typer.confirm(question, default=False, err=True)   # stdout stays clean for --json


JSON_OPT = typer.Option(False, "--json", help="Machine-readable output with stable keys.")
