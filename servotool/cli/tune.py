"""`servotool tune inertia`: identify the load inertia ratio, set it, suggest and set gains."""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import Any

import typer

from servotool.cli.common import confirm, drive, resolved
from servotool.cli.jog import confirm_motion
from servotool.cli.render import emit_json, info, out, table, warn
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.model.codec import as_held, raw_to_eng
from servotool.model.profile import Profile
from servotool.motion import deadman
from servotool.ops import eeprom
from servotool.tuning import budget, gain_search, identify, planning, preflight, step, tune
from servotool.tuning.control.friction import friction_report
from servotool.tuning.errors import TravelNeeded, TuneDeclined

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


def _gains_json(changes: Any) -> list[dict[str, Any]]:
    return [
        {
            "role": c.role,
            "code": c.entry.code,
            "old": as_held(c.entry, c.old),
            "new": as_held(c.entry, c.new),
            "unit": c.entry.unit,
        }
        for c in changes
    ]


def _step_json(response: step.StepResponse | None) -> dict[str, Any] | None:
    if response is None:
        return None
    summary = response.summary()
    return {**summary, **{k: _rounded(summary[k], 2) for k in ("overshoot_pct", "settling_ms", "ripple_pct")}}


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
        "coulomb_nm": _sig(est.coulomb_nm) if est else None,
        "coulomb_std_nm": _sig(est.coulomb_std_nm) if est else None,
        "viscous_nm_per_rad_s": _sig(est.viscous_nm_per_rad_s) if est else None,
        "load_torque_nm": _sig(est.load_torque_nm) if est else None,
        "load_torque_std_nm": _sig(est.load_torque_std_nm) if est else None,
        "residual_rel": _rounded(est.residual_rel, 4) if est else None,
        "notes": list(est.notes) if est else [],
        "samples": len(result.trace.t),
        "samples_per_s": round(result.samples_per_s, 1),
        "travel_rev": round(result.travel_used_rev, 3) if result.travel_used_rev is not None else None,
        "time_s": round(result.time_used_s, 2),
        "cycles": result.cycles,
        **_needs_json(result.plan),
    }


def _needs_json(plan: planning.MotionPlan | None) -> dict[str, Any]:
    """What the line needed, as said before moving (the motor alone), and the time budget the motion had."""
    needs = plan.needs if plan is not None else None
    if needs is None:
        return {}
    return {
        "needed_travel_rev": needs.lightest.travel_rev if needs.lightest.reachable else None,
        "needed_time_s": _rounded(needs.lightest.time_s, 1) if needs.lightest.reachable else None,
        "time_budget_s": _rounded(plan.time_budget_s, 1) if plan is not None else None,
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
        help="Step check after writing gains; on failure the "
        "previous gains go back (default: on with the simulated drive).",
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
    verify = check if check is not None else resolved(ctx).simulated
    request = tune.TuneRequest(
        force=force,
        verify=verify and (rigidity is not None or bandwidth is not None),
        method=method,
        max_speed=max_speed,
        accel_time_ms=accel_time,
        travel_rev=travel,
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
    if step_check:
        step.step_duration_s(travel)  # refused before the drive is opened

    with drive(ctx) as d:
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
        except ServoError as exc:  # refused, tripped, travel exceeded, link lost
            _failed(exc, report, d.profile, as_json and (ask.moving or isinstance(exc, TravelNeeded)))
            raise
        profile = d.profile
    if report is not None:
        _report(report, res.identified, profile, res)
    _render(res, profile, as_json, ask.dead_man)


def _failed(exc: ServoError, report: Path | None, profile: Profile, as_json: bool) -> None:
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
        emit_json(
            _clean(
                {
                    "ok": False,
                    "reason": str(exc),
                    **(_estimate_json(refused) if refused else {}),
                    "ratio": refused.new_ratio if refused else None,
                    "written": False,
                    "suggested_travel_rev": suggested,
                    "needed_travel_rev": needed.travel_rev if needed is not None else None,
                    "needed_time_s": _rounded(needed.time_s, 1) if needed is not None else None,
                    "moved": needed.moved if needed is not None else True,
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

    def approve_motion(self, motion: planning.MotionPlan | None) -> bool:
        if self.method == "host" or self.step_check:
            confirm_motion(self.ctx, self.d, self.yes, preflight.FEATURE)
        info(
            f"motion: {motion.describe()}"
            if motion is not None
            else "motion: the drive's own identification (its parameters set torque and travel), then host "
            "moves that check its result"
        )
        if motion is not None and motion.needs is not None:
            info(f"needs: {motion.needs.words()}")
        if self.step_check:
            info(
                f"step check: {step.STEP_SPEED_RPM:g} rpm for {step.step_duration_s(self.travel):.2f} s forward "
                "and back, before and after"
            )
        if self.method == "host" and motion is not None:
            self.dead_man = deadman.motion_bound(self.d, motion.speed_rpm, motion.ramp_s)
        elif self.step_check:
            self.dead_man = deadman.motion_bound(self.d, step.STEP_SPEED_RPM, 0.0)
        if self.dead_man is not None:
            info(deadman.sentence(self.dead_man))
        self.moving = confirm("Move the axis now?", self.yes)
        return self.moving

    def choose_travel(self, needs: budget.Needs) -> float | None:
        """Asked once, before moving, where the line needs more travel than the default allows."""
        light = needs.lightest
        if not light.reachable or not sys.stdin.isatty():
            return None
        info(f"needs: {needs.words()}")
        if confirm(f"Allow {light.travel_rev:g} rev of travel (the axis must have the room)?", False):
            self.travel = light.travel_rev
            return light.travel_rev
        return None

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
    return {
        "coulomb_pct": _rounded(report.coulomb_pct, 2),
        "viscous_pct_at_rated_speed": _rounded(report.viscous_pct_at_rated, 2),
        "load_pct": _rounded(report.load_pct, 2),
        "compensation": {s.entry.code: as_held(s.entry, s.value) for s in report.settings},
    }


def _report(
    folder: Path, result: identify.Result, profile: Profile, res: tune.TuneResult | None, reason: str = ""
) -> None:
    from servotool.report.tune_report import write_tune_report

    written = write_tune_report(folder, result, profile, res, reason)
    info(f"report: {len(written.files)} files in {folder} (open {folder / 'report.md'})")


def _render(
    res: tune.TuneResult, profile: Profile, as_json: bool, dead_man: deadman.DeadManBound | None = None
) -> None:
    """The outcome, after the writes."""
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
                    "parameter_value": raw_to_eng(entry, proposal.parameter_raw)
                    if entry and proposal.parameter_raw is not None
                    else None,
                    "written": res.ratio_stored,
                    "persisted": res.persisted,
                    "gains": _gains_json(changes),
                    "gains_written": res.gains_written,
                    "bandwidth_hz": _rounded(sugg.bandwidth_hz, 2) if sugg else None,
                    "rigidity": sugg.rigidity if sugg else None,
                    "phase_margin_deg": _rounded(proposal.margins.phase_deg, 1) if proposal.margins else None,
                    "gain_margin_db": _rounded(proposal.margins.gain_db, 1) if proposal.margins else None,
                    "step_before": _step_json(res.step_before),
                    "step_after": _step_json(res.step_after),
                    "dead_man": dead_man.as_json() if dead_man is not None else None,
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


def _show(proposal: tune.Proposal) -> None:
    """What was identified and would be written, shown before asking to write it."""
    result, entry, sugg, changes = proposal.identified, proposal.parameter, proposal.suggestion, proposal.gain_changes
    est = result.estimate
    old = f"{result.old_ratio:.2f}" if result.old_ratio is not None else "(not a drive parameter)"
    param = f"  ({entry.code} = {proposal.parameter_value:g} {entry.unit})" if entry is not None else ""
    out.print(
        f"load inertia ratio (J_load/J_motor): {old} -> {result.new_ratio:.2f}"
        + (f" ± {est.ratio_std:.2f}" if est else "")
        + param,
        markup=False,
    )
    if est:
        travel = f"{result.travel_used_rev:.2f} rev, " if result.travel_used_rev is not None else ""
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
                    f"  friction compensation (suggested, not written): {s.entry.code} = {s.value:g} "
                    f"{s.entry.unit} ({s.what})",
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
            t.add_row(c.entry.code, c.entry.name, f"{c.old:g}", f"{c.new:g}", c.entry.unit)  # the role: in JSON
        out.print(t)
        if proposal.margins is not None:
            out.print(f"margins on the identified inertia: {proposal.margins.describe()}", markup=False)


@app.command("gains")
def gains(
    ctx: typer.Context,
    load_ratio: float = typer.Option(
        None,
        "--load-ratio",
        help="J_load/J_motor to tune for (default: the drive's inertia-ratio parameter, as tune inertia wrote it).",
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

    with drive(ctx) as d:
        d.dead_man_waived = no_dead_man
        confirm_motion(ctx, d, yes, "tune gains")
        if not confirm("Move the axis now (a speed step forward and back at each level)?", yes):
            raise typer.Exit(1)
        try:
            res = gain_search.search_gains(
                d, load_ratio=load_ratio, start=start, top=top, travel_rev=travel, save=save, progress=show
            )
        except gain_search.GainSearchFailed as exc:
            _render_search(exc.search, as_json, ok=False)
            raise
        profile = d.profile
    if res.persisted is False:
        warn(eeprom.ram_only_warning(profile))
    _render_search(res, as_json, ok=True)


def _render_search(res: gain_search.GainSearch, as_json: bool, ok: bool) -> None:
    rows = [
        {
            "level": t.level,
            "speed_gain_hz": round(t.speed_gain_hz, 2),
            "phase_margin_deg": round(t.margins.phase_deg, 1),
            "gain_margin_db": _clean(round(t.margins.gain_db, 1)),
            "overshoot_pct": _rounded(t.response.overshoot_pct, 2) if t.response else None,
            "settling_ms": _rounded(t.response.settling_ms, 2) if t.response else None,
            "ripple_pct": round(t.response.ripple_pct, 2) if t.response else None,
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
                    "levels": rows,
                    "chosen": res.chosen,
                    "reason": res.reason,
                    "gains": _gains_json(res.changes),
                    "persisted": res.persisted,
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
        title=f"rigidity levels tried (load ratio {res.load_ratio:.2f})",
    )
    for r in rows:
        settle = f"{r['settling_ms']:.0f} ms" if r["settling_ms"] is not None else "-"
        over = f"{r['overshoot_pct']:.0f} %" if r["overshoot_pct"] is not None else "-"
        gm = f"{r['gain_margin_db']:.1f} dB" if r["gain_margin_db"] is not None else "inf"
        t.add_row(
            str(r["level"]),
            f"{r['speed_gain_hz']:.1f} Hz",
            f"{r['phase_margin_deg']:.0f}°, {gm}",
            over,
            settle,
            r["failure"] or "ok",
        )
    out.print(t)
    if res.chosen is not None:
        out.print(
            f"{res.reason}; kept level {res.chosen}: "
            + ", ".join(f"{c.entry.code} {c.old:g} -> {c.new:g}" for c in res.changes),
            markup=False,
        )
