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
from servotool.cli.render import Verbosity, caution, emit_json, err, info, notice, safety
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.quantity import quantity
from servotool.model.roles import FEATURE
from servotool.motion.caveats import motion_caveats
from servotool.motion.deadman import DeadManBound, lines
from servotool.motion.hold import HoldToRun
from servotool.motion.jog_plan import JogPlan
from servotool.motion.setup import check_setup
from servotool.motion.stop import StopReport, proven_on_interrupt
from servotool.motion.travel import TravelLimit
from servotool.ops.trace import Sampler, motion_entries
from servotool.ops.trace_file import check_writable, write_trace
from servotool.sim.state import effective_values
from servotool.tuning.stable_hold import guarded_jogger

KEYS = "→/d forward  ←/a reverse  space stop  q quit"


def travel_limit(ctx: typer.Context, travel: float | None) -> TravelLimit | None:
    """The soft travel limit: --travel, else the environment or config file's 'travel'."""
    if travel is not None:
        return TravelLimit(travel, "--travel")
    configured = resolved(ctx).travel
    return TravelLimit(configured, "config file / SERVOTOOL_TRAVEL") if configured is not None else None


def confirm_motion(ctx: typer.Context, d: Drive, yes: bool, feature: str = FEATURE) -> list[str]:
    """Refuse while the drive lacks its motion setup; on a real port name the unverified motion entries (ask
    before moving) and a missing drive-side watchdog. Returns the cautions given (for --json)."""
    simulated = resolved(ctx).simulated
    # A real drive reads back a power-cycle value before it acts on it; the simulator says what is in effect.
    check_setup(d, feature, partial(effective_values, d.profile, d.unit) if simulated else None)
    if simulated:
        return []
    caveats = motion_caveats(d.profile, feature)
    lines = caveats.lines()
    caution(lines)
    if caveats.unverified:
        codes = ", ".join(e.code for _, e, _ in caveats.unverified)
        if not confirm(f"Move the motor through unverified entries ({codes})?", yes):
            raise ServoError("cancelled: nothing moved")
    return lines


@contextmanager
def _traced(ctx: typer.Context, d: Drive, path: Path | None) -> Iterator[Sampler | None]:
    """The JOG's speed read back to back between its keep-alive beats, as fast as the line allows (its peak is
    then the line's, not the beat's); with a path, a recording of its motion, written however the JOG ends
    (stopped, failed, interrupted)."""
    speed = d.profile.role("speed_feedback")
    if path is None:
        yield Sampler(d, [speed]) if speed is not None else None
        return
    from servotool.cli.trace import about_lines

    sampler = Sampler(d, motion_entries(d.profile))
    try:
        yield sampler
    finally:
        if sampler.samples:
            rec = sampler.recording()
            about = about_lines(
                resolved(ctx),
                f"trigger: none (the JOG's own motion, sampled between keep-alive "
                f"beats); {sampler.requests_per_sample} request(s) per sample",
            )
            write_trace(path, [rec], sampler.entries, about, replace=True)
            info(f"trace: {rec.timing.describe()} written to {path}")


def jog(
    ctx: typer.Context,
    speed: float = typer.Option(..., "--speed", "-s", help="JOG speed in rpm; negative runs in reverse."),
    seconds: float = typer.Option(None, "--time", "-t", help="Run this long, then ramp down and stop."),
    interactive: bool = typer.Option(
        False,
        "--interactive",
        "-i",
        help=f"Keyboard control, hold-to-run: the motor moves only while a direction key is held. {KEYS}.",
    ),
    toggle: bool = typer.Option(
        False,
        "--toggle",
        help="With --interactive: a direction key starts the motion and space stops it (no need to hold the key).",
    ),
    max_travel: float = typer.Option(None, "--max-travel", help="Refuse a timed JOG longer than this (revolutions)."),
    travel: float = typer.Option(
        None,
        "--travel",
        help="Soft travel limit: revolutions either way from where the "
        "JOG starts, checked before and during motion (default: 'travel' in the config "
        "file or SERVOTOOL_TRAVEL; none).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Print the plan and the result as JSON."),
    yes: bool = typer.Option(
        False,
        "--yes",
        "-y",
        help="Do not ask before moving through unverified entries (real drives only; the simulator never asks).",
    ),
    no_dead_man: bool = typer.Option(
        False,
        "--no-dead-man",
        help="Move a drive that has no dead-man route (nothing "
        "stops the motor if this program dies); keep an E-stop at hand.",
    ),
    trace_file: Path = typer.Option(
        None,
        "--trace",
        help="Record speed, torque and position between the "
        "keep-alive beats, on the same port, to this CSV ('servotool plot' draws it).",
    ),
) -> None:
    """JOG the motor. Before moving it prints what stops the motor if this program stops, and the bound."""
    _check_options(seconds, interactive, toggle, trace_file)
    show = _Speeds(seconds)
    with drive(ctx) as d, _traced(ctx, d, trace_file) as sampler, proven_on_interrupt(d):
        d.dead_man_waived = no_dead_man
        jogger = guarded_jogger(d)
        if sampler is not None:
            jogger.idle = sampler.sample_for
            show.sampler = sampler
        plan = jogger.plan(speed, seconds, max_travel, travel_limit(ctx, travel))
        cautions = confirm_motion(ctx, d, yes)
        info(
            plan.describe() + ("" if not interactive else f"  [{'toggle' if toggle else 'hold a key to move'}: {KEYS}]")
        )
        if plan.dead_man is not None:
            for line in lines(plan.dead_man):
                safety(line)
        try:
            if interactive:
                hold = None if toggle else HoldToRun(jogger.clock, jogger.keepalive_s)
                with raw_keys() as key:

                    def command() -> int | None:
                        k = key()
                        if k == "quit":
                            return None
                        pressed = {"fwd": 1, "rev": -1, "stop": 0}.get(k or "")
                        if hold is not None:
                            return hold.key(pressed)
                        return jogger.direction if pressed is None else pressed

                    jogger.run(plan, show, command)
            else:
                jogger.run(plan, show)
        except KeyboardInterrupt:
            if err.is_terminal:
                err.print("")  # after the speed line; the last line says what the stop read back
            raise
        if err.is_terminal:
            err.print("")
    _result(plan, seconds, show, jogger.last_stop, as_json, cautions)


def _result(
    plan: JogPlan,
    seconds: float | None,
    show: _Speeds,
    stopped: StopReport | None,
    as_json: bool,
    cautions: list[str],
) -> None:
    final = stopped.speed_rpm if stopped is not None else None
    sign = plan.direction if seconds is not None else 1  # a timed reverse JOG peaks at a negative speed
    peak, rate = show.measured_peak()
    if as_json:
        emit_json(
            {
                "speed": quantity(plan.speed_rpm * plan.direction, "rpm"),
                "time": quantity(seconds, "s"),
                "ramp": quantity(plan.accel_ms, "ms", text=plan.ramp or None),
                "peak_speed": quantity(round(peak, 1) * sign, "rpm"),
                "speed_sample_rate": quantity(round(rate, 1) if rate is not None else None, "Hz"),
                "median_speed": quantity(round(statistics.median(show.late), 1) * sign if show.late else None, "rpm"),
                "final_speed": quantity(final, "rpm"),
                "dead_man": plan.dead_man.as_json() if plan.dead_man is not None else None,
                "safety": safety_lines(plan.dead_man, cautions),
                "stop": stopped.as_json() if stopped is not None else None,
            }
        )
    else:
        now = f"{final:g} rpm" if final is not None else "?"
        notice(f"JOG done: peak {peak * sign:.1f} rpm{_coarse(rate)}, now {now}")  # a result


def _coarse(rate: float | None) -> str:
    """How finely the peak was sampled: the speed read as fast as the line allows between the beats."""
    if rate is None:
        return ""
    return f" (speed read {rate:.0f} times a second)"


def safety_lines(bound: DeadManBound | None, cautions: list[str]) -> list[str]:
    """The safety lines printed before moving, for --json: the dead-man bound (or NO DEAD-MAN), what else bounds
    the motion (protections, forced inputs), and the cautions."""
    return (lines(bound) if bound is not None else []) + cautions


def _check_options(seconds: float | None, interactive: bool, toggle: bool, trace_file: Path | None) -> None:
    if (seconds is None) == (not interactive):
        raise UsageError("give exactly one of --time SECONDS or --interactive")
    if toggle and not interactive:
        raise UsageError("--toggle goes with --interactive")
    if interactive and not sys.stdin.isatty():
        raise UsageError("--interactive needs a terminal")
    if trace_file is not None:
        check_writable(trace_file, replace=True)


class _Speeds:
    """The JOG's speed as it runs: shown on a terminal, its peak, and the speeds over the second half of a timed
    JOG (the speed it settled at)."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds, self.peak = seconds, 0.0
        self.late: list[float] = []
        self.sampler: Sampler | None = None  # the speed read between the beats

    def measured_peak(self) -> tuple[float, float | None]:
        """The peak speed over the sampler's readings (the JOG's --trace: its peak is the trace's; the beats'
        readings between them would add noise draws the trace does not show), else over the beats', and how many
        readings a second the sampler made (None without one)."""
        if self.sampler is None or len(self.sampler.samples) < 2:
            return self.peak, None
        code = self.sampler.entries[0].code
        samples = self.sampler.samples
        peak = max(abs(s.values[code]) for s in samples)
        span = samples[-1].t - samples[0].t
        return peak, (len(samples) - 1) / span if span > 0 else None

    def __call__(self, t: float, rpm: float | None) -> None:
        if rpm is not None:
            self.peak = max(self.peak, abs(rpm))
            if self.seconds is None or t >= self.seconds / 2:
                self.late.append(abs(rpm))
        if Verbosity.level >= 0 and err.is_terminal:
            sys.stderr.write(f"\r t={t:5.1f} s  speed={rpm if rpm is not None else float('nan'):8.1f} rpm ")
            sys.stderr.flush()
