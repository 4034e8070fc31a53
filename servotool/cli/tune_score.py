"""`servotool tune score` and `tune compare`: the machine's response measured, saved and compared."""

from __future__ import annotations

from pathlib import Path

import typer

from servotool.cli.common import boosted, confirm, drive
from servotool.cli.jog import confirm_motion
from servotool.cli.render import emit_json, info, out, table
from servotool.errors import UsageError
from servotool.motion.stop import proven_on_interrupt
from servotool.tuning import score as scoring
from servotool.tuning.fit.score import FIGURES, Difference, Figure, Score

app = typer.Typer(no_args_is_help=True, help="Score the machine's response and compare scores.")

LABELS = {
    "overshoot": "overshoot",
    "settling": "settling (5 %)",
    "following_error_rms": "following error RMS",
    "following_error_peak": "following error peak",
    "iae": "integrated abs. error",
    "ripple": "speed ripple",
    "torque_rms": "torque RMS",
    "ringing": "ringing",
}


def _writable(path: Path | None) -> None:
    if path is not None and (path.is_dir() or not (path.parent if str(path.parent) else Path(".")).is_dir()):
        raise UsageError(f"cannot write the score to {path}")


@app.command("score")
def score(
    ctx: typer.Context,
    repeats: int = typer.Option(
        scoring.DEFAULT_REPEATS, "--repeats", help="Runs of the test motion (2 or more give the spread)."
    ),
    travel: float = typer.Option(2.0, "--travel", help="Travel limit of the test motion in revolutions."),
    speed: float = typer.Option(200.0, "--speed", help="Test speed in rpm."),
    save: Path = typer.Option(None, "--save", "-o", help="Save the score to this JSON file (for tune compare)."),
    before: Path = typer.Option(None, "--before", help="A saved score to compare this one with (this one is 'after')."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    no_dead_man: bool = typer.Option(
        False,
        "--no-dead-man",
        help="Move a drive that has no dead-man route (nothing stops the motor if this program dies).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Run one standard test motion (a speed step, then a trapezoidal move back) and score the response.

    Overshoot, settling, following error, integrated error, ripple, torque RMS and ringing, each with its spread
    over the repeats and how coarse the line's sampling makes it. Nothing is written to the drive but the test
    motion's own JOG settings, put back afterwards.
    """
    motion = scoring.motion_for(travel, speed)
    scoring.check_repeats(repeats)
    _writable(save)
    old = scoring.load(before) if before is not None else None
    with drive(ctx) as d, proven_on_interrupt(d), boosted(ctx, [d], "the test motion"):
        d.dead_man_waived = no_dead_man
        motion = scoring.planned(d, motion)
        if old is not None and (why := scoring.comparable(old[1], motion)):
            raise UsageError(f"{before}: {why}")
        confirm_motion(ctx, d, yes, "tune score")
        if not confirm(f"Move the axis now ({motion.describe()}, {repeats} times)?", yes):
            raise typer.Exit(1)

        def show(n: int, _run: Score) -> None:
            if not as_json:
                info(f"run {n} of {repeats} done")

        measured = scoring.measure(d, motion, repeats, progress=show)
        profile_id = d.profile.id
    if save is not None:
        try:
            scoring.save(measured, save, profile_id)
        except OSError as exc:
            raise UsageError(f"cannot write {save}: {exc.strerror}") from None
    data = scoring.score_json(measured, profile_id)
    if old is not None:
        diffs, overall = scoring.compare(old[0], measured.score)
        data["comparison"] = scoring.comparison_json(diffs, overall)
    if as_json:
        emit_json(data)
        return
    render_score(measured.score, motion.describe())
    if save is not None:
        out.print(f"saved to {save}", markup=False)
    if old is not None:
        render_comparison(*scoring.compare(old[0], measured.score))


@app.command("compare")
def compare(
    before: Path = typer.Argument(..., help="The score before the change (tune score --save)."),
    after: Path = typer.Argument(..., help="The score after it."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Compare two saved scores: each figure's difference, judged only beyond the measurements' own spread."""
    a, b = scoring.load(before), scoring.load(after)
    why = scoring.comparable(a[1], b[1])
    if why:
        raise UsageError(f"cannot compare {before} and {after}: {why}")
    diffs, overall = scoring.compare(a[0], b[0])
    if as_json:
        emit_json(scoring.comparison_json(diffs, overall))
        return
    render_comparison(diffs, overall)


def _text(name: str, f: Figure, spread: bool = True) -> str:
    unit = FIGURES[name][0]
    if f.value is None:
        return "never settles" if name == "settling" else "none seen"
    digits = 4 if unit == "rev" else 1
    text = f"{f.value:.{digits}f} {unit}"
    if spread and f.spread:
        text += f" ± {f.spread:.{digits}f}"
    return text


def render_score(s: Score, motion: str) -> None:
    t = table("Figure", "Value (± spread)", "Sampling resolution", title=f"score of {s.runs} run(s): {motion}")
    for name, f in s.figures.items():
        unit = FIGURES[name][0]
        t.add_row(LABELS[name], _text(name, f), f"{f.resolution:.{4 if unit == 'rev' else 1}f} {unit}")
    out.print(t)
    out.print(
        f"sampled at {s.rate_hz:.0f}/s: nothing above {s.nyquist_hz:.0f} Hz (the Nyquist limit) is visible",
        markup=False,
    )


def render_comparison(diffs: list[Difference], overall: str) -> None:
    t = table("Figure", "Before", "After", "Must differ by", "Verdict")
    for d in diffs:
        unit = FIGURES[d.name][0]
        t.add_row(
            LABELS[d.name],
            _text(d.name, d.before),
            _text(d.name, d.after),
            f"{d.margin:.{4 if unit == 'rev' else 1}f} {unit}",
            d.verdict,
        )
    out.print(t)
    out.print(f"verdict: {overall.upper()} (beyond the spread of the repeats and the sampling)", markup=False)
