"""`servotool jog`: timed or interactive JOG with a dead-man."""

from __future__ import annotations

import statistics
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import typer

from servotool.cli.common import confirm, drive, resolved
from servotool.cli.keys import raw_keys
from servotool.cli.render import Verbosity, caution, emit_json, err, info
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.roles import FEATURE
from servotool.motion.caveats import motion_caveats
from servotool.motion.jogger import Jogger
from servotool.motion.setup import check_setup
from servotool.ops.trace import Sampler, motion_entries
from servotool.ops.trace_file import check_writable, write_trace
from servotool.sim.state import effective_values

KEYS = "→/d forward  ←/a reverse  space stop  q quit"


def confirm_motion(ctx: typer.Context, d: Drive, yes: bool, feature: str = FEATURE) -> None:
    """Refuse while the drive lacks its motion setup; on a real port name the unverified motion entries (ask
    before moving) and a missing drive-side watchdog."""
    simulated = resolved(ctx).simulated
    # A real drive reads back a power-cycle value before it acts on it; the simulator says what is in effect.
    check_setup(d, feature, partial(effective_values, d.profile, d.unit) if simulated else None)
    if simulated:
        return
    caveats = motion_caveats(d.profile, feature)
    caution(caveats.lines())
    if caveats.unverified:
        codes = ", ".join(e.code for _, e, _ in caveats.unverified)
        if not confirm(f"Move the motor through unverified entries ({codes})?", yes):
            raise ServoError("cancelled: nothing moved")


@contextmanager
def _traced(ctx: typer.Context, d: Drive, path: Path | None) -> Iterator[Sampler | None]:
    """A recording of the JOG's own motion, written however the JOG ends (stopped, failed, interrupted)."""
    if path is None:
        yield None
        return
    from servotool.cli.trace import about_lines

    sampler = Sampler(d, motion_entries(d.profile))
    try:
        yield sampler
    finally:
        if sampler.samples:
            rec = sampler.recording()
            about = about_lines(resolved(ctx), f"trigger: none (the JOG's own motion, sampled between keep-alive "
                                f"beats); {sampler.requests_per_sample} request(s) per sample")
            write_trace(path, [rec], sampler.entries, about, replace=True)
            info(f"trace: {rec.timing.describe()} written to {path}")


def jog(
    ctx: typer.Context,
    speed: float = typer.Option(..., "--speed", "-s", help="JOG speed in rpm; negative runs in reverse."),
    seconds: float = typer.Option(None, "--time", "-t", help="Run this long, then ramp down and stop."),
    interactive: bool = typer.Option(False, "--interactive", "-i", help=f"Keyboard control: {KEYS}."),
    max_travel: float = typer.Option(None, "--max-travel", help="Refuse a timed JOG longer than this (revolutions)."),
    as_json: bool = typer.Option(False, "--json", help="Print the plan and the result as JSON."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving through unverified entries "
                             "(real drives only; the simulator never asks)."),
    trace_file: Path = typer.Option(None, "--trace", help="Record speed, torque and position between the "
                                    "keep-alive beats, on the same port, to this CSV ('servotool plot' draws it)."),
) -> None:
    """JOG the motor; the drive stops by itself if this program goes quiet. Ctrl-C stops at once."""
    if (seconds is None) == (not interactive):
        raise UsageError("give exactly one of --time SECONDS or --interactive")
    if interactive and not sys.stdin.isatty():
        raise UsageError("--interactive needs a terminal")
    if trace_file is not None:
        check_writable(trace_file, replace=True)
    with drive(ctx) as d, _traced(ctx, d, trace_file) as sampler:
        jogger = Jogger(d)
        if sampler is not None:
            jogger.idle = sampler.sample_for
        plan = jogger.plan(speed, seconds, max_travel)
        confirm_motion(ctx, d, yes)
        info(plan.describe() + ("" if not interactive else f"  [{KEYS}]"))
        peak = 0.0
        late: list[float] = []    # speeds over the second half of a timed JOG: the speed it settled at

        def show(t: float, rpm: float | None) -> None:
            nonlocal peak
            if rpm is not None:
                peak = max(peak, abs(rpm))
                if seconds is None or t >= seconds / 2:
                    late.append(abs(rpm))
            if Verbosity.level >= 0 and err.is_terminal:
                sys.stderr.write(f"\r t={t:5.1f} s  speed={rpm if rpm is not None else float('nan'):8.1f} rpm ")
                sys.stderr.flush()

        try:
            if interactive:
                with raw_keys() as key:
                    def command() -> int | None:
                        k = key()
                        if k == "quit":
                            return None
                        return {"fwd": 1, "rev": -1, "stop": 0}.get(k or "", jogger.direction)
                    jogger.run(plan, show, command)
            else:
                jogger.run(plan, show)
        except KeyboardInterrupt:
            err.print("\nservotool: JOG stopped by Ctrl-C", markup=False)
            raise typer.Exit(130) from None
        if err.is_terminal:
            err.print("")
        final = jogger.speed()
    sign = plan.direction if seconds is not None else 1      # a timed reverse JOG peaks at a negative speed
    if as_json:
        emit_json({"speed_rpm": plan.speed_rpm * plan.direction, "time_s": seconds,
                   "peak_speed_rpm": round(peak, 1) * sign,
                   "median_speed_rpm": round(statistics.median(late), 1) * sign if late else None,
                   "final_speed_rpm": final})
    else:
        info(f"JOG done: peak {peak * sign:.1f} rpm, now {final if final is not None else '?'} rpm")
