"""Glue between typer's context and the library: connection options, opening drives."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import typer

from servotool.cli import render
from servotool.cli.render import Verbosity, info, trace_frame, warn
from servotool.connection import ConnectOptions, Resolved, resolve
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.session import open_drives


class State:
    """What the root command's options said (a plain class: each dataclass compiles its methods at start-up)."""

    def __init__(self, options: ConnectOptions | None = None) -> None:
        self.options = options if options is not None else ConnectOptions()


def state(ctx: typer.Context) -> State:
    root = ctx.find_root()
    if root.obj is None:
        root.obj = State()
    return root.obj


def resolved(ctx: typer.Context) -> Resolved:
    return resolve(state(ctx).options)


def notice_for(ctx: typer.Context) -> Callable[[str], None]:
    """What opening a drive has to say, for the user: the manual's line numbers only with -v, a suggested command
    with the user's connection options. Only the simulator's banner goes with --quiet: the rest are warnings and
    what a killed servotool process left on the drive (and how it was put right)."""
    given = state(ctx).options

    def notice(line: str) -> None:
        if line.startswith("servotool: SIMULATED"):  # session.sim_notice: the banner
            info(line)
            return
        from servotool.cli.messages import plain, with_options

        render.notice(with_options(plain(line, Verbosity.level > 0), given))

    return notice


@contextmanager
def drive(ctx: typer.Context) -> Iterator[Drive]:
    """The one drive the global options point at; after a command that completed, names each entry the drive
    turned out to lack (once, however often it was asked for)."""
    with open_drives(
        resolved(ctx), trace=trace_frame if Verbosity.level > 0 else None, notice=notice_for(ctx)
    ) as drives:
        yield drives[0]
        for e in drives[0].missing.values():
            warn(f"{e.code} ({e.name}): not on this drive (exception 02 for its address); left out")


@contextmanager
def drives(ctx: typer.Context, units: list[int]) -> Iterator[list[Drive]]:
    with open_drives(
        resolved(ctx), units, trace=trace_frame if Verbosity.level > 0 else None, notice=notice_for(ctx)
    ) as found:
        yield found


def confirm(question: str, yes: bool) -> bool:
    """Ask before something irreversible; without a terminal, refuse (exit 2) rather than hang."""
    if yes:
        return True
    if not sys.stdin.isatty():
        raise UsageError(f"'{question}' needs confirmation: run in a terminal or pass --yes")
    return typer.confirm(question, default=False, err=True)  # stdout stays clean for --json


JSON_OPT = typer.Option(False, "--json", help="Machine-readable output with stable keys.")
