"""Glue between typer's context and the library: connection options, opening drives."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import typer

from servotool.cli import render
from servotool.cli.render import Verbosity, info, trace_frame, warn
from servotool.connection import ConnectOptions, Resolved
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.session import Bus, open_drives, resolve_or_find

if TYPE_CHECKING:
    from servotool.ops.boost import BoostFacts
    from servotool.ops.scan import Found


class State:
    """One command's options, and what they resolved to; in `servotool shell`, the bus it keeps open. A plain
    class: each dataclass compiles its methods at start-up."""

    def __init__(
        self,
        options: ConnectOptions | None = None,
        bus: Bus | None = None,
        line_options: Callable[[ConnectOptions], tuple[ConnectOptions, Resolved]] | None = None,
    ) -> None:
        self.options = options if options is not None else ConnectOptions()
        self.resolved: Resolved | None = None
        self.bus = bus
        # in the shell: a typed line's global options over the shell's own, checked (cli.shell.line_options)
        self.line_options = line_options


def state(ctx: typer.Context) -> State:
    root = ctx.find_root()
    if root.obj is None:
        root.obj = State()
    return root.obj


def take_options(ctx: typer.Context, given: ConnectOptions) -> None:
    """The global options of a command line; in the shell, over those it was opened with (cli.shell)."""
    st = state(ctx)
    if st.line_options is not None:
        st.options, st.resolved = st.line_options(given)
        return
    st.options, st.resolved = given, None


def resolved(ctx: typer.Context) -> Resolved:
    """The options resolved, once a command; on a real port without --profile, the profile found (and said)."""
    st = state(ctx)
    if st.resolved is None:
        st.resolved = resolved_from(st.options)
    return st.resolved


def resolved_from(options: ConnectOptions) -> Resolved:
    res, found = resolve_or_find(options, trace_frame if Verbosity.level > 0 else None)
    if found is not None:
        info(found_text(found, res))
    return res


def found_text(found: Found, res: Resolved) -> str:
    """'servotool: found: Inovance IS620P (profile is620p) by H01-00 = 0, H01-01 = 0 and 1 more'."""
    from servotool.ops.identity import FITS

    p = res.profile
    verdict = next(v for v in found.ranked if v.profile.id == p.id)
    fits = sorted((a for a in verdict.answers if a.verdict == FITS), key=lambda a: a.check.range is None)
    said = [f"{a.check.label} = {a.raw}" if a.raw is not None else f"{a.check.label} absent" for a in fits]
    by = ", ".join(said[:2]) + (f" and {len(said) - 2} more" if len(said) > 2 else "")
    vendor = "" if p.vendor.startswith("unknown") else p.vendor.split(" (")[0] + " "
    at = f" at {found.line.baud} baud {found.line.describe().split()[1]}" if found.line else ""
    return f"servotool: found: {vendor}{p.model} (profile {p.id}){at} by {by}"


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
    """The one drive the global options point at (in the shell, on the port it keeps open); after a command that
    completed, names each entry the drive turned out to lack (once, however often it was asked for)."""
    with _drives(ctx, None) as found:
        yield found[0]
        for e in found[0].missing.values():
            warn(f"{e.code} ({e.name}): not on this drive (exception 02 for its address); left out")


@contextmanager
def _drives(ctx: typer.Context, units: list[int] | None, bare: bool = False) -> Iterator[list[Drive]]:
    res = resolved(ctx)
    if (bus := state(ctx).bus) is not None:
        yield bus.drives(units or [res.unit], bare=bare)
        return
    trace = trace_frame if Verbosity.level > 0 else None
    with open_drives(res, units, trace=trace, notice=notice_for(ctx), bare=bare) as found:
        yield found


@contextmanager
def drives(ctx: typer.Context, units: list[int], bare: bool = False) -> Iterator[list[Drive]]:
    """Drives for these units (in the shell, on its open port); bare: see session.Bus.drives."""
    with _drives(ctx, units, bare) as found:
        yield found


@contextmanager
def drives_for(ctx: typer.Context, res: Resolved, units: list[int]) -> Iterator[list[Drive]]:
    """Drives for what a command resolved itself (run: a plan's options under the command line's); in the shell,
    on its open port, which must be the one resolved."""
    if (bus := state(ctx).bus) is not None:
        open_on = bus.resolved
        if (res.settings.port, res.profile.id) != (open_on.settings.port, open_on.profile.id):
            raise UsageError(
                f"the shell keeps {open_on.settings.port} open ({open_on.profile.id}), not "
                f"{res.settings.port} ({res.profile.id}): leave it to use another"
            )
        yield bus.drives(units)
        return
    with open_drives(res, units, trace=trace_frame if Verbosity.level > 0 else None, notice=notice_for(ctx)) as found:
        yield found


@contextmanager
def boosted(
    ctx: typer.Context, found: list[Drive], what: str, *, allow: bool = True, res: Resolved | None = None
) -> Iterator[BoostFacts]:
    """The line raised for a long exchange (identification, trace, backup, restore) as --boost/--no-boost and the
    profile allow (ops.boost); allow=False keeps the factory line (a restore that writes the baud entry). res: the
    options a command resolved itself (a plan's)."""
    from servotool.ops.boost import line_boost

    res = res or resolved(ctx)
    with line_boost(
        found, res.boost if allow else False, sole=res.simulated, notice=notice_for(ctx), what=what
    ) as facts:
        yield facts


def confirm(question: str, yes: bool) -> bool:
    """Ask before something irreversible; without a terminal, refuse (exit 2) rather than hang."""
    if yes:
        return True
    if not sys.stdin.isatty():
        raise UsageError(f"'{question}' needs confirmation: run in a terminal or pass --yes")
    return typer.confirm(question, default=False, err=True)  # stdout stays clean for --json


JSON_OPT = typer.Option(False, "--json", help="Machine-readable output with stable keys.")
