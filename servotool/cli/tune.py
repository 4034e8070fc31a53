"""`servotool tune inertia`: identify the load inertia ratio, set it, suggest and set gains."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from servotool.cli.common import boosted, confirm, drive, resolved
from servotool.cli.jog import confirm_motion, safety_lines
from servotool.cli.render import emit_json, err, info, out, safety, table, warn
from servotool.cli.values import json_mark, spoken, unit_text
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.codec import as_held, raw_to_eng
from servotool.model.profile import Profile
from servotool.model.quantity import quantity
from servotool.motion import deadman, protect, stop
from servotool.ops import eeprom
from servotool.tuning import budget, gain_search, identify, planning, preflight, step, tune
from servotool.tuning.control.friction import friction_report
from servotool.tuning.errors import TravelNeeded, TuneDeclined

if TYPE_CHECKING:
    from servotool.ops.boost import BoostFacts

app = typer.Typer(no_args_is_help=True, help="Identify load inertia and set gains.")
DEFAULT_TRAVEL_REV = 2.0


def _clean(value: Any) -> Any:
    """JSON has no NaN/Infinity: unknown numbers become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def _sig(value: float | None, digits: int = 4) -> float | None:
    """A measured figure to the digits it carries (JSON gave 0.024729362562792387 N·m for a friction)."""
    return None if value is None or not math.isfinite(value) else float(f"{value:.{digits}g}")


def _rounded(value: float | None, decimals: int) -> float | None:
    return None if value is None or not math.isfinite(value) else round(value, decimals)


def _gains_json(changes: Any, profile: Profile | None = None) -> list[dict[str, Any]]:
    return [
        {
            "role": c.role,
            "code": c.entry.code,
            "old": as_held(c.entry, c.old),
            "new": as_held(c.entry, c.new),
            "unit": c.entry.unit,
            "value_unverified": json_mark(profile, c.entry) if profile is not None else None,
        }
        for c in changes
    ]


def _step_json(response: step.StepResponse | None) -> dict[str, Any] | None:
    return response.summary() if response is not None else None


STEP_FIGURES = ("overshoot", "settling", "ripple", "interval", "overshoot_bound")


def _check_options(
    method: str, rigidity: int | None, bandwidth: float | None, no_gains: bool, save_trace: Path | None
) -> None:
    """Everything that can be checked without the drive, before anything moves."""
    if method not in ("host", "drive"):
        raise UsageError("--method must be host or drive")
    if rigidity is not None and bandwidth is not None:
        raise UsageError("give --rigidity or --bandwidth, not both")
    if no_gains and (rigidity is not None or bandwidth is not None):
        raise UsageError("--no-gains contradicts --rigidity/--bandwidth")
    if save_trace is not None:
        parent = save_trace.parent if str(save_trace.parent) else Path(".")
        if (
            save_trace.is_dir()
            or not parent.is_dir()
            or not os.access(parent, os.W_OK)
            or (save_trace.exists() and not os.access(save_trace, os.W_OK))
        ):
            raise UsageError(f"cannot write the trace to {save_trace}")


def _estimate_json(result: identify.Result) -> dict[str, Any]:
    est = result.estimate
    return {
        "method": result.method,
        "old_ratio": round(result.old_ratio, 4) if result.old_ratio is not None else None,
        "ratio_std": _sig(est.ratio_std) if est else None,
        "coulomb": quantity(_sig(est.coulomb_nm), "N·m", std=_sig(est.coulomb_std_nm)) if est else None,
        "viscous": quantity(_sig(est.viscous_nm_per_rad_s), "N·m·s/rad") if est else None,
        "load_torque": quantity(_sig(est.load_torque_nm), "N·m", std=_sig(est.load_torque_std_nm)) if est else None,
        "residual_rel": _rounded(est.residual_rel, 4) if est else None,
        "notes": list(est.notes) if est else [],
        "samples": len(result.trace.t),
        "samples_left_out": result.trace.late,  # their exchange overran the line's time: when taken is not known
        "sample_rate": quantity(round(result.samples_per_s, 1), "Hz"),
        "travel": quantity(round(result.travel_used_rev, 3) if result.travel_used_rev is not None else None, "rev"),
        "time": quantity(round(result.time_used_s, 2), "s"),
        "cycles": result.cycles,
        **_needs_json(result.plan),
    }


def _needs_json(plan: planning.MotionPlan | None) -> dict[str, Any]:
    """What the line needed, as said before moving (the motor alone), the most the run was to take (said then too),
    and the time budget the motion had."""
    needs = plan.needs if plan is not None else None
    if needs is None:
        return {}
    light = needs.named
    return {
        "needed_travel": quantity(light.travel_rev if light is not None else None, "rev"),
        "needed_time": quantity(_rounded(light.time_s, 1) if light is not None else None, "s"),
        "time_limit": quantity(_rounded(plan.time_limit_s, 1) if plan is not None else None, "s"),
        "time_budget": quantity(_rounded(plan.time_budget_s, 1) if plan is not None else None, "s"),
    }


@app.command("inertia")
def inertia(
    ctx: typer.Context,
    method: str = typer.Option(
        "host", "--method", help="host: servotool moves and fits; drive: the drive's own identification function."
    ),
    max_speed: float = typer.Option(None, "--max-speed", help="Highest test speed in rpm (default: from --travel)."),
    accel_time: float = typer.Option(
        None, "--accel-time", help="Ramp time of each move in ms (default: from the link's sampling rate, 100..500 ms)."
    ),
    travel: float = typer.Option(
        None,
        "--travel",
        help="Travel limit: range of axis positions in revolutions (default 2). More travel, stronger "
        "accelerations: before moving servotool says what the line needs, and asks for it once in a terminal.",
    ),
    direction: str = typer.Option(
        "both",
        "--direction",
        help="both (out and back, load torque separated from "
        "friction), forward or reverse (only; friction and load torque fitted as one).",
    ),
    repeats: int = typer.Option(
        None,
        "--repeats",
        help="Number of move cycles (default: repeat until the estimate is precise, within about 9 s).",
    ),
    rigidity: int = typer.Option(
        None,
        "--rigidity",
        help="Set gains for the drive's own rigidity level N (its own "
        "range, anchored at its factory gains); also writes its rigidity parameter.",
    ),
    bandwidth: float = typer.Option(None, "--bandwidth", help="Set gains for this speed-loop bandwidth in Hz."),
    no_gains: bool = typer.Option(
        False, "--no-gains", help="Leave the gains alone (the default unless --rigidity or --bandwidth is given)."
    ),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask: move, then write the results."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Identify and show results; write nothing."),
    save_trace: Path = typer.Option(
        None,
        "--save-trace",
        "--trace",
        help="Save the sampled speed/torque to this "
        "CSV (also when the identification is refused); 'servotool plot' draws it.",
    ),
    report: Path = typer.Option(
        None,
        "--report",
        metavar="DIR",
        help="Write a report folder: PNG charts of the motion, the fit, "
        "each move, the step response and the gains, with report.md (needs servotool[plot]).",
    ),
    step_check: bool = typer.Option(
        False,
        "--step-check",
        help="Measure a speed step (overshoot, settling) "
        "before and after; moves out and back inside --travel each time.",
    ),
    save: bool = typer.Option(
        None,
        "--save/--no-save",
        help="Store the written ratio and gains in EEPROM (or keep "
        "them out of it) as the drive allows; default: the drive's current setting.",
    ),
    no_dead_man: bool = typer.Option(
        False,
        "--no-dead-man",
        help="Move a drive that has no dead-man route "
        "(nothing stops the motor if this program dies); keep an E-stop at hand.",
    ),
    force: bool = typer.Option(False, "--force", help="Write gains even with under 45° phase or 6 dB gain margin."),
    check: bool = typer.Option(
        None,
        "--check/--no-check",
        help="Step check after writing gains; on failure the previous gains go back (default: on with the "
        "simulated drive; a real drive asks, and without a terminal needs one of the two).",
    ),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Identify the load inertia ratio (with friction and gravity), write it, and set matching gains.

    Gains are changed only with --rigidity or --bandwidth.
    """
    given_travel = travel is not None
    travel = travel if travel is not None else DEFAULT_TRAVEL_REV
    _check_options(method, rigidity, bandwidth, no_gains, save_trace)
    if report is not None:
        from servotool.report.tune_report import check_folder

        check_folder(report)
    writes_gains = (rigidity is not None or bandwidth is not None) and not dry_run
    request = tune.TuneRequest(
        force=force,
        verify=_step_check_choice(ctx, check, writes_gains, yes),
        method=method,
        max_speed=max_speed,
        accel_time_ms=accel_time,
        travel_rev=travel,
        travel_given=given_travel,
        direction=direction,
        repeats=repeats,
        gains=rigidity is not None or bandwidth is not None,
        rigidity=rigidity,
        bandwidth_hz=bandwidth,
        save=save,
        dry_run=dry_run,
        step_check=step_check,
        trace_path=save_trace,
    )
    tune.check_request(resolved(ctx).profile, request)  # refused before the drive is opened (or its line raised)

    # An interrupt before the first motion, between motions or at a prompt ends with the drive read back.
    with drive(ctx) as d, stop.proven_on_interrupt(d), boosted(ctx, [d], "the identification") as line:
        d.dead_man_waived = no_dead_man
        ask = _Dialog(ctx, d, yes=yes, method=method, step_check=step_check, travel=travel, as_json=as_json)
        try:
            res = tune.tune_inertia(
                d,
                request,
                progress=info,
                approve_motion=ask.approve_motion,
                on_proposal=ask.show,
                approve_write=ask.approve_write,
                choose_travel=None if yes or given_travel or as_json else ask.choose_travel,
            )
        except TuneDeclined:
            raise typer.Exit(1) from None
        except KeyboardInterrupt as exc:
            _notes(exc)
            raise
        except ServoError as exc:  # refused, tripped, travel exceeded, link lost
            _failed(exc, report, d.profile, as_json and (ask.moving or isinstance(exc, TravelNeeded)), line)
            raise
        profile = d.profile
    if report is not None:
        _report(report, res.identified, profile, res)
    _render(res, profile, as_json, ask.dead_man, ask.safety + ask.cautions, line)


def _notes(interrupt: KeyboardInterrupt) -> None:
    """What an interrupt left said before it leaves (typer turns it into a bare exit 130): the gains written back,
    or the new ones that stay."""
    for note in getattr(interrupt, "__notes__", ()):
        err.print(f"servotool: {note}", markup=False)


CHECK_WHAT = "a 200 rpm step forward and back once they are written; the previous gains go back if it fails"


def _step_check_choice(ctx: typer.Context, check: bool | None, writes_gains: bool, yes: bool) -> bool:
    """Whether the gains are step-checked once written: as --check/--no-check say; on the simulated drive, yes; on
    a real one the choice is the user's: asked in a terminal, else a usage error (before anything moves)."""
    if not writes_gains:
        return False
    if check is not None:
        return check
    if resolved(ctx).simulated:
        return True
    if yes or not sys.stdin.isatty():
        raise UsageError(f"writing gains on a real drive needs --check ({CHECK_WHAT}) or --no-check")
    return typer.confirm(f"Step-check the gains ({CHECK_WHAT})?", default=True, err=True)


def _failed(
    exc: ServoError, report: Path | None, profile: Profile, as_json: bool, line: BoostFacts | None = None
) -> None:
    """What a failed identification leaves: the report of a refused one, and the JSON of any (the reason, the
    estimate so far, the travel a refusal suggests)."""
    refusal = exc if isinstance(exc, identify.IdentificationRefused) else None
    refused = refusal.result if refusal is not None else None
    if report is not None and refused is not None:
        _report(report, refused, profile, None, str(exc))
    if as_json:
        cure = refusal.remedy if refusal is not None else None
        needed = exc if isinstance(exc, TravelNeeded) else None
        suggested = cure.suggested_rev if cure is not None else needed.travel_rev if needed is not None else None
        rolled = exc.facts if isinstance(exc, tune.GainsRolledBack) else {}
        emit_json(
            _clean(
                {
                    "ok": False,
                    "reason": str(exc),
                    **(_estimate_json(refused) if refused else {}),
                    # refused: no ratio stands (what was measured is in the report); rolled back: it does
                    "ratio": round(exc.ratio, 4) if isinstance(exc, tune.GainsRolledBack) and exc.ratio else None,
                    "written": bool(rolled.get("kept")),  # a rollback keeps the ratio written before the gains
                    "suggested_travel": quantity(suggested, "rev"),
                    "needed_travel": quantity(needed.travel_rev if needed is not None else None, "rev"),
                    "needed_time": quantity(_rounded(needed.time_s, 1) if needed is not None else None, "s"),
                    "moved": needed.moved if needed is not None else True,
                    "rolled_back": bool(rolled),
                    "rollback_reason": rolled.get("reason"),
                    "step_check": _step_json(exc.response) if isinstance(exc, tune.GainsRolledBack) else None,
                    "line": line.as_json() if line is not None else None,
                }
            )
        )


class _Dialog:
    """What `tune inertia` asks and tells the user while the use case runs: before moving (the motion, the
    dead-man bound), the proposal, before writing."""

    def __init__(
        self, ctx: typer.Context, d: Drive, *, yes: bool, method: str, step_check: bool, travel: float, as_json: bool
    ) -> None:
        self.ctx, self.d, self.yes, self.method = ctx, d, yes, method
        self.step_check, self.travel, self.as_json = step_check, travel, as_json
        self.moving = False  # identifying: a failure now reports what was measured
        self.dead_man: deadman.DeadManBound | None = None
        self.cautions: list[str] = []
        self.safety: list[str] = []  # the safety lines printed (for --json)

    def approve_motion(self, motion: planning.MotionPlan | None) -> bool:
        if self.method == "host" or self.step_check:
            self.cautions = confirm_motion(self.ctx, self.d, self.yes, preflight.FEATURE)
        info(
            f"motion: {motion.describe()}"
            if motion is not None
            else "motion: the drive's own identification (its parameters set torque and travel), then host "
            "moves that check its result"
        )
        if motion is not None and motion.needs is not None:
            info(f"needs: {motion.needs.words()}")
        if self.method == "host" and motion is not None:
            bound = planning.identification_bound(self.d, motion)
            deadman.check(bound, self.d.dead_man_waived)
            self.dead_man = protect.planned_bound(self.d, bound, motion.speed_rpm, motion.travel_limit_rev)
            for line in deadman.lines(self.dead_man):
                self._safety(line)
        if self.step_check:
            check = step.plan_step(self.d, self.travel)
            info(f"step check: {check.describe()}, before and after")
            if self.dead_man is None:  # the step check's bound, with the protections it sets
                self.dead_man = protect.planned_bound(self.d, check.bound, check.speed_rpm, self.travel)
                first, *more = deadman.lines(self.dead_man)
                for line in (f"step check: {first}", *more):
                    self._safety(line)
            else:
                self._safety(f"step check: {deadman.sentence(check.bound)}")
        self.moving = confirm("Move the axis now?", self.yes)
        return self.moving

    def choose_travel(self, needs: budget.Needs) -> float | None:
        """Asked once, before moving, where the line needs more travel than the default allows."""
        light = needs.named
        if light is None or not sys.stdin.isatty():
            return None
        info(f"needs: {needs.words()}")
        if confirm(f"Allow {light.travel_rev:g} rev of travel (the axis must have the room)?", False):
            self.travel = light.travel_rev
            return light.travel_rev
        return None

    def _safety(self, line: str) -> None:
        safety(line)
        self.safety.append(line)

    def show(self, proposal: tune.Proposal) -> None:
        self.moving = False
        if not self.as_json:
            _show(proposal)

    def approve_write(self, proposal: tune.Proposal) -> bool:
        entry = proposal.parameter
        question = (
            (
                f"Write {entry.code} = {proposal.parameter_value:g} {entry.unit}"
                + (" and the gains" if proposal.gain_changes else "")
                + "?"
            )
            if proposal.writes_ratio and entry is not None
            else "Write the gains?"
        )
        return confirm(question, self.yes)


def _friction_json(profile: Profile, est: Any) -> dict[str, Any] | None:
    report = friction_report(profile, est) if est is not None else None
    if report is None:
        return None
    rated = "% of rated torque"
    return {
        "coulomb": quantity(_rounded(report.coulomb_pct, 2), rated),
        "viscous_at_rated_speed": quantity(_rounded(report.viscous_pct_at_rated, 2), rated),
        "load": quantity(_rounded(report.load_pct, 2), rated),
        "compensation": {
            s.entry.code: quantity(
                as_held(s.entry, s.value), s.entry.unit, value_unverified=json_mark(profile, s.entry)
            )
            for s in report.settings
        },
    }


def _report(
    folder: Path, result: identify.Result, profile: Profile, res: tune.TuneResult | None, reason: str = ""
) -> None:
    from servotool.report.tune_report import write_tune_report

    written = write_tune_report(folder, result, profile, res, reason)
    info(f"report: {len(written.files)} files in {folder} (open {folder / 'report.md'})")


def _stop_json() -> dict[str, Any] | None:
    """What the last motion's stop read back (motion/stop.py), for --json."""
    report = stop.final()
    return report.as_json() if report is not None else None


def _render(
    res: tune.TuneResult,
    profile: Profile,
    as_json: bool,
    dead_man: deadman.DeadManBound | None = None,
    cautions: list[str] | None = None,
    line: BoostFacts | None = None,
) -> None:
    """The outcome, after the writes (cautions: the safety lines and cautions given before moving; line: the speed
    the identification ran at, where a boost raised it)."""
    proposal, sugg = res.proposal, res.proposal.suggestion
    entry, changes = proposal.parameter, proposal.gain_changes
    if as_json:
        emit_json(
            _clean(
                {
                    "ok": True,
                    **_estimate_json(res.identified),
                    "ratio": round(res.ratio, 4),
                    "friction": _friction_json(profile, res.identified.estimate),
                    "parameter": entry.code if entry else None,
                    "parameter_value": quantity(
                        raw_to_eng(entry, proposal.parameter_raw),
                        entry.unit,
                        value_unverified=json_mark(profile, entry),
                    )
                    if entry and proposal.parameter_raw is not None
                    else None,
                    "written": res.ratio_stored,
                    "persisted": res.persisted,
                    "gains": _gains_json(changes, profile),
                    "gains_written": res.gains_written,
                    "line": line.as_json() if line is not None else None,
                    "bandwidth": quantity(_rounded(sugg.bandwidth_hz, 2), "Hz") if sugg else None,
                    "rigidity": sugg.rigidity if sugg else None,
                    "phase_margin": quantity(_rounded(proposal.margins.phase_deg, 1), "°")
                    if proposal.margins
                    else None,
                    "gain_margin": quantity(_rounded(proposal.margins.gain_db, 1), "dB") if proposal.margins else None,
                    "step_before": _step_json(res.step_before),
                    "step_after": _step_json(res.step_after),
                    "dead_man": dead_man.as_json() if dead_man is not None else None,
                    "safety": cautions or [],
                    "stop": _stop_json(),
                }
            )
        )
        return
    if res.persisted is False:
        warn(eeprom.ram_only_warning(profile))
    what = (
        f"{entry.code} {'written' if res.ratio_stored else 'not written'}"
        if entry
        else f"nothing to write: {profile.id} maps no inertia-ratio parameter"
    )
    out.print(
        what
        + (
            f", gains {'written' if res.gains_written else 'not written'}"
            if changes
            else " (gains unchanged: give --rigidity N or --bandwidth HZ to set them)"
        ),
        markup=False,
    )
    est = res.identified.estimate
    for note in est.notes if est else []:
        info(note)
    if res.step_before is not None:
        out.print(f"step before: {res.step_before.describe()}", markup=False)
    if res.step_after is not None:
        label = "step check after writing the gains:" if res.verified is not None else "step after: "
        out.print(f"{label} {res.step_after.describe()}", markup=False)
    if (sampled := res.step_after or res.step_before) is not None:
        out.print(f"step {sampled.sampling()}", markup=False)


def _show(proposal: tune.Proposal) -> None:
    """What was identified and would be written, shown before asking to write it."""
    result, entry, sugg, changes = proposal.identified, proposal.parameter, proposal.suggestion, proposal.gain_changes
    est = result.estimate
    old = f"{result.old_ratio:.2f}" if result.old_ratio is not None else "(not a drive parameter)"
    param = f"  ({entry.code} = {spoken(proposal.profile, entry, f'{proposal.parameter_value:g}')})" if entry else ""
    out.print(
        f"load inertia ratio (J_load/J_motor): {old} -> {result.new_ratio:.2f}"
        + (f" ± {est.ratio_std:.2f}" if est else "")
        + param,
        markup=False,
    )
    if est:
        travel = f"{result.travel_used_rev:.2f} rev, " if result.travel_used_rev is not None else ""
        peaks = [m.peak_rpm for m in est.moves if math.isfinite(m.peak_rpm)]
        travel += f"moves reached {min(peaks):.0f}-{max(peaks):.0f} rpm, " if peaks else ""
        out.print(
            f"friction {est.coulomb_nm:.4f} ± {est.coulomb_std_nm:.4f} N·m, viscous "
            f"{est.viscous_nm_per_rad_s:.2e} N·m·s/rad, load torque {est.load_torque_nm:.4f} ± "
            f"{est.load_torque_std_nm:.4f} N·m, fit residual {est.residual_rel:.1%}; "
            f"{len(result.trace.t)} samples ({result.samples_per_s:.0f}/s), {travel}"
            f"{result.time_used_s:.1f} s",
            markup=False,
        )
        report = friction_report(proposal.profile, est)
        if report is not None:
            out.print(f"in drive units: {report.describe()}", markup=False)
            for s in report.settings:
                out.print(
                    f"  friction compensation (suggested, not written): {s.entry.code} = "
                    f"{spoken(proposal.profile, s.entry, f'{s.value:g}')} ({s.what})",
                    markup=False,
                )
    if changes and sugg is not None:
        t = table(
            "Code",
            "Name",
            "Current",
            "Suggested",
            "Unit",
            title=f"gains for {sugg.bandwidth_hz:.1f} Hz speed-loop gain"
            + (f" (rigidity {sugg.rigidity})" if sugg.rigidity is not None else ""),
        )
        for c in changes:
            unit = unit_text(proposal.profile, c.entry)
            t.add_row(c.entry.code, c.entry.name, f"{c.old:g}", f"{c.new:g}", unit)  # the role: in JSON
        out.print(t)
        if proposal.margins is not None:
            out.print(f"margins on the identified inertia: {proposal.margins.describe()}", markup=False)


@app.command("gains")
def gains(
    ctx: typer.Context,
    load_ratio: float = typer.Option(
        None,
        "--load-ratio",
        help="J_load/J_motor to tune for (default: the drive's inertia-ratio parameter, as tune inertia wrote it; "
        "given, the margins are those of this load under the drive's own ratio, which is not written).",
    ),
    start: int = typer.Option(None, "--from", help="First rigidity level to try (default: the drive's current)."),
    top: int = typer.Option(None, "--to", help="Highest level to try (default: the highest the margins allow)."),
    travel: float = typer.Option(2.0, "--travel", help="Travel limit of each step check in revolutions."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask before moving."),
    save: bool = typer.Option(
        None,
        "--save/--no-save",
        help="Store the chosen gains in EEPROM (or keep them out "
        "of it) as the drive allows; default: the drive's current setting.",
    ),
    no_dead_man: bool = typer.Option(
        False,
        "--no-dead-man",
        help="Move a drive that has no dead-man route "
        "(nothing stops the motor if this program dies); keep an E-stop at hand.",
    ),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Raise the drive's own rigidity level step by step with a step check at each; keep a safe level.

    Stops at the first level that overshoots, rings or trips, backs off one level and writes that level's gains
    (and the rigidity parameter where the drive has one). Levels beyond 45° / 6 dB of computed margin are not tried.
    """
    step.step_duration_s(travel)

    def show(trial: gain_search.LevelTrial) -> None:
        if not as_json:
            info(
                f"level {trial.level}: {trial.speed_gain_hz:.1f} Hz, "
                + (trial.response.describe() if trial.response else "no response")
                + (f": FAILED ({trial.failure})" if trial.failure else "")
            )

    with drive(ctx) as d, stop.proven_on_interrupt(d), boosted(ctx, [d], "the step checks"):
        d.dead_man_waived = no_dead_man
        cautions = confirm_motion(ctx, d, yes, "tune gains")
        check = step.plan_step(d, travel)  # the bound of each level's step check, with the protections it sets
        bound = protect.planned_bound(d, check.bound, check.speed_rpm, travel)
        info(f"step check: {check.describe()}, at each level")
        for line in deadman.lines(bound):
            safety(line)
        if not confirm("Move the axis now (a speed step forward and back at each level)?", yes):
            raise typer.Exit(1)
        try:
            res = gain_search.search_gains(
                d, load_ratio=load_ratio, start=start, top=top, travel_rev=travel, save=save, progress=show
            )
        except KeyboardInterrupt as exc:
            _notes(exc)
            raise
        except gain_search.GainSearchFailed as exc:
            _render_search(exc.search, as_json, ok=False, safety_json=safety_lines(bound, cautions), bound=bound)
            raise
        profile = d.profile
    if res.persisted is False:
        warn(eeprom.ram_only_warning(profile))
    _render_search(res, as_json, ok=True, safety_json=safety_lines(bound, cautions), bound=bound)


def _render_search(
    res: gain_search.GainSearch,
    as_json: bool,
    ok: bool,
    safety_json: list[str] | None = None,
    bound: deadman.DeadManBound | None = None,
) -> None:
    rows = [
        {
            "level": t.level,
            "speed_gain": quantity(round(t.speed_gain_hz, 2), "Hz"),
            "phase_margin": quantity(_rounded(t.margins.phase_deg, 1), "°"),
            "gain_margin": quantity(_rounded(t.margins.gain_db, 1), "dB"),
            **{k: (t.response.summary()[k] if t.response else None) for k in STEP_FIGURES},
            "failure": t.failure,
        }
        for t in res.trials
    ]
    if as_json:
        emit_json(
            _clean(
                {
                    "ok": ok,
                    "load_ratio": _rounded(res.load_ratio, 4),
                    "drive_ratio": _rounded(res.own_ratio, 4) if res.own_ratio is not None else None,
                    "levels": rows,
                    "chosen": res.chosen,
                    "reason": res.reason,
                    "gains": _gains_json(res.changes),
                    "persisted": res.persisted,
                    "dead_man": bound.as_json() if bound is not None else None,
                    "safety": safety_json or [],
                    "stop": _stop_json(),
                }
            )
        )
        return
    # Six columns and a wrapping Result fit 80 (the settling time goes first where a failure's words need room).
    t = table(
        "Level",
        "Speed gain",
        "Margins",
        "Overshoot",
        "Settling",
        "Result",
        drop=("Settling",),
        title=f"rigidity levels tried (load ratio {res.load_ratio:.2f}"
        + (
            ")"
            if res.own_ratio is None or abs(res.own_ratio - res.load_ratio) < 0.005
            else f"; the drive's own {res.own_ratio:.2f}, by which it scales its speed gain, left as it is)"
        ),
    )
    for r in rows:
        settle = f"{r['settling']['value']:.0f} ms" if r["settling"] is not None else "-"
        over = f"{r['overshoot']['value']:.0f} %" if r["overshoot"] is not None else "-"
        gm = f"{r['gain_margin']['value']:.1f} dB" if r["gain_margin"] is not None else "inf"
        t.add_row(
            str(r["level"]),
            f"{r['speed_gain']['value']:.1f} Hz",
            f"{r['phase_margin']['value']:.0f}°, {gm}",
            over,
            settle,
            r["failure"] or "ok",
        )
    out.print(t)
    sampled = next((t.response for t in res.trials if t.response is not None), None)
    if sampled is not None:
        out.print(f"step checks {sampled.sampling()}", markup=False)
    if res.chosen is not None:
        out.print(
            f"{res.reason}; kept level {res.chosen}: "
            + ", ".join(f"{c.entry.code} {c.old:g} -> {c.new:g}" for c in res.changes),
            markup=False,
        )
