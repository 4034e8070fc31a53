"""`servotool tune friction`, `tune notch` and `tune resonance`: the drive's own functions, run and judged."""

from __future__ import annotations

from pathlib import Path

import typer

from servotool.cli.common import boosted, confirm, drive
from servotool.cli.jog import confirm_motion
from servotool.cli.render import emit_json, info, out, warn
from servotool.cli.tune_score import render_comparison, render_score
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.quantity import quantity
from servotool.motion.stop import proven_on_interrupt
from servotool.ops import eeprom
from servotool.tuning import drive_functions as functions
from servotool.tuning import function_run as use
from servotool.tuning import gain_switching as gs
from servotool.tuning import score as scoring

app = typer.Typer(no_args_is_help=True, help="Run the drive's own tuning functions, judged by a measured score.")

REPEATS_HELP = "Runs of the test motion before and after (2 or more give the spread the verdict needs)."
TRAVEL_HELP = "Travel limit of the test motion in revolutions."
KEEP_HELP = "Keep the change even where the score did not improve beyond its spread."
SAVE_HELP = "Store a kept change in EEPROM (or keep it out of it) as the drive allows; default: the drive's setting."
REPORT_HELP = "Write the before/after chart and the score table to DIR (needs servotool[plot])."
DEAD_MAN_HELP = "Move a drive that has no dead-man route (nothing stops the motor if this program dies)."


def _start(
    ctx: typer.Context, d: Drive, yes: bool, no_dead_man: bool, what: str, motion: scoring.ScoreMotion
) -> scoring.ScoreMotion:
    """Ask before moving (the motion as planned for this drive and travel) and return that motion."""
    d.dead_man_waived = no_dead_man
    motion = scoring.planned(d, motion)
    confirm_motion(ctx, d, yes, f"tune {what}")
    if not confirm(f"Move the axis now ({motion.describe()}, several times)?", yes):
        raise typer.Exit(1)
    return motion


def _progress(as_json: bool) -> functions.Progress:
    return (lambda _text: None) if as_json else info


@app.command("friction")
def friction(
    ctx: typer.Context,
    repeats: int = typer.Option(scoring.DEFAULT_REPEATS, "--repeats", help=REPEATS_HELP),
    travel: float = typer.Option(2.0, "--travel", help=TRAVEL_HELP),
    keep: bool = typer.Option(False, "--keep", help=KEEP_HELP),
    save: bool = typer.Option(None, "--save/--no-save", help=SAVE_HELP),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    no_dead_man: bool = typer.Option(False, "--no-dead-man", help=DEAD_MAN_HELP),
    report: Path = typer.Option(None, "--report", metavar="DIR", help=REPORT_HELP),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Friction compensation from the torques at constant speed, kept only where the score improves.

    The SDC manual's procedure for every drive that maps compensation entries: a run each way below 10 r/min
    gives the Coulomb terms, the torque at the test speed less them the damping terms (where mapped). Scored
    before and after on following error and integrated error; put back otherwise.
    """
    _run(ctx, "friction", None, repeats, travel, keep, save, yes, no_dead_man, report, as_json)


@app.command("notch")
def notch(
    ctx: typer.Context,
    method: str = typer.Option(
        None,
        "--method",
        help="drive: the drive's own adaptive notch, read back (default where the profile maps one); host: at a "
        "peak of the score's spectrum.",
    ),
    repeats: int = typer.Option(scoring.DEFAULT_REPEATS, "--repeats", help=REPEATS_HELP),
    travel: float = typer.Option(2.0, "--travel", help=TRAVEL_HELP),
    keep: bool = typer.Option(False, "--keep", help=KEEP_HELP),
    save: bool = typer.Option(None, "--save/--no-save", help=SAVE_HELP),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    no_dead_man: bool = typer.Option(False, "--no-dead-man", help=DEAD_MAN_HELP),
    report: Path = typer.Option(None, "--report", metavar="DIR", help=REPORT_HELP),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """A torque-command notch at the machine's resonance, kept only where the score improves.

    --method drive runs the drive's adaptive notch while the test motion excites the machine and reads back what
    it set; --method host notches only a peak the line's sampling resolves (below 80 % of the Nyquist limit) inside
    the drive's notch range. Put back where the score does not improve beyond its spread.
    """
    _run(ctx, "notch", method, repeats, travel, keep, save, yes, no_dead_man, report, as_json)


def _run(
    ctx: typer.Context,
    function: str,
    method: str | None,
    repeats: int,
    travel: float,
    keep: bool,
    save: bool | None,
    yes: bool,
    no_dead_man: bool,
    report: Path | None,
    as_json: bool,
    factor: float | None = None,
) -> None:
    """The one use case (tuning.function_run.run_function), asked for and rendered."""
    if method not in (None, *use.METHODS):
        raise UsageError("--method must be drive or host")
    motion = scoring.motion_for(travel)
    scoring.check_repeats(repeats)
    _check_report(report)
    with drive(ctx) as d, proven_on_interrupt(d), boosted(ctx, [d], f"tune {function}"):
        use.check_function(d.profile, function, method)
        use.check_entries(d, function)
        eeprom.check_save_request(d.profile, save)
        motion = _start(ctx, d, yes, no_dead_man, function, motion)
        trial = use.run_function(
            d,
            function,
            motion,
            repeats,
            method=method,
            keep=keep,
            save=save,
            factor=factor,
            progress=_progress(as_json),
        )
        profile = d.profile
    _report(report, trial)
    _render(trial, as_json, profile.id)


@app.command("gain-switching")
def gain_switching(
    ctx: typer.Context,
    factor: float = typer.Option(
        1.5, "--factor", help="Gain 2's speed-loop gain and integral time against gain 1's, above 1, at most 4."
    ),
    repeats: int = typer.Option(scoring.DEFAULT_REPEATS, "--repeats", help=REPEATS_HELP),
    travel: float = typer.Option(2.0, "--travel", help=TRAVEL_HELP),
    keep: bool = typer.Option(False, "--keep", help=KEEP_HELP),
    save: bool = typer.Option(None, "--save/--no-save", help=SAVE_HELP),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    no_dead_man: bool = typer.Option(False, "--no-dead-man", help=DEAD_MAN_HELP),
    report: Path = typer.Option(None, "--report", metavar="DIR", help=REPORT_HELP),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """A stiffer second gain set while the motor turns, the first at rest, kept only where the score improves.

    On the speed condition the manual documents (SD25 Po130 = 2: above Po131 gain 2 at once, below it gain 1
    after Po135): gain 2 is gain 1's speed gain and integral time times --factor. Judged on following error,
    integrated error, overshoot and settling; put back otherwise. Refused where the manual does not describe the
    conditions (IS620P H08-09).
    """
    gs.check_factor(factor)
    _run(ctx, "gain-switching", None, repeats, travel, keep, save, yes, no_dead_man, report, as_json, factor)


@app.command("resonance")
def resonance(
    ctx: typer.Context,
    travel: float = typer.Option(2.0, "--travel", help=TRAVEL_HELP),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    no_dead_man: bool = typer.Option(False, "--no-dead-man", help=DEAD_MAN_HELP),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Find resonances: the spectrum of speed and torque after a speed step, at the line's full rate.

    Says what the line can see (nothing above its Nyquist limit) and proposes a notch only for a peak it resolves
    inside the drive's notch range. Writes nothing.
    """
    motion = scoring.motion_for(travel)
    with drive(ctx) as d, proven_on_interrupt(d), boosted(ctx, [d], "tune resonance"):
        motion = _start(ctx, d, yes, no_dead_man, "resonance", motion)
        measured = scoring.measure(d, motion, 1)
        peaks, nyquist = functions.resonance_peaks(measured)
        proposal = functions.notch_proposal(d, peaks, nyquist)
    data = {
        "sample_rate": quantity(round(2 * nyquist, 1), "Hz"),
        "nyquist": quantity(round(nyquist, 1), "Hz"),
        "peaks": [use.peak_json(p) for p in peaks],
        "notch": proposal,
    }
    if as_json:
        emit_json(data)
        return
    out.print(f"sampled at {2 * nyquist:.0f}/s: nothing above {nyquist:.0f} Hz is visible on this line", markup=False)
    for p in peaks:
        seen = "resolved" if p.resolvable else "NOT RESOLVED (near the Nyquist limit: perhaps a higher one, folded)"
        out.print(f"peak {p.hz:.1f} Hz, amplitude {p.amplitude:.2f}: {seen}", markup=False)
    if not peaks:
        out.print("no peak stands out of the spectrum", markup=False)
    out.print(proposal["reason"], markup=False)


def _check_report(folder: Path | None) -> None:
    if folder is not None:
        from servotool.report.tune_report import check_folder

        check_folder(folder)


def _report(folder: Path | None, trial: functions.FunctionTrial) -> None:
    if folder is not None:
        from servotool.report.function_report import write

        for path in write(folder, trial):
            info(f"wrote {path}")


def _render(trial: functions.FunctionTrial, as_json: bool, profile_id: str) -> None:
    data = use.trial_json(trial, profile_id)
    if as_json:
        emit_json(data)
        return
    if trial.after is None and trial.before is not None:
        render_score(trial.before.score, trial.before.motion.describe())
    if trial.after is not None:
        render_comparison(trial.differences, trial.verdict)
        out.print(f"judged on: {', '.join(functions.JUDGED.get(trial.function, ()))}", markup=False)
    out.print(f"{'KEPT' if trial.kept else 'NOT KEPT'}: {trial.reason}", markup=False)
    if trial.held:
        held = ", ".join(f"{code} = {value:g}" for code, value in trial.held.items())
        out.print(f"the drive holds {held} (read back)", markup=False)
    if trial.kept and trial.persisted is False:
        warn("the kept values are in RAM only: a power cycle loses them (--save stores them where the drive can)")
