"""`servotool tune inertia`: identify the load inertia ratio, set it, suggest and set gains."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import typer

from servotool.cli.common import confirm, drive
from servotool.cli.jog import confirm_motion
from servotool.cli.render import emit_json, info, out, table, warn
from servotool.errors import ServoError, UsageError
from servotool.ops import eeprom
from servotool.tuning import gain_writes, identify, planning, preflight, step
from servotool.tuning.gains import suggest_gains

app = typer.Typer(no_args_is_help=True, help="Identify load inertia and set gains.")


def _clean(value: Any) -> Any:
    """JSON has no NaN/Infinity: unknown numbers become null."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_clean(v) for v in value]
    return value


def _check_options(method: str, rigidity: int | None, bandwidth: float | None, no_gains: bool,
                   save_trace: Path | None) -> None:
    """Everything that can be checked without the drive, before anything moves."""
    if method not in ("host", "drive"):
        raise UsageError("--method must be host or drive")
    if rigidity is not None and bandwidth is not None:
        raise UsageError("give --rigidity or --bandwidth, not both")
    if no_gains and (rigidity is not None or bandwidth is not None):
        raise UsageError("--no-gains contradicts --rigidity/--bandwidth")
    if rigidity is not None or bandwidth is not None:
        try:   # the rules the gains will be computed with, on a nominal load
            suggest_gains(rotor_inertia_kgcm2=1.0, load_ratio=1.0, rigidity=rigidity, bandwidth_hz=bandwidth)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    if save_trace is not None:
        parent = save_trace.parent if str(save_trace.parent) else Path(".")
        if save_trace.is_dir() or not parent.is_dir() or not os.access(parent, os.W_OK) or \
                (save_trace.exists() and not os.access(save_trace, os.W_OK)):
            raise UsageError(f"cannot write the trace to {save_trace}")


def _estimate_json(result: identify.Result) -> dict[str, Any]:
    est = result.estimate
    return {
        "method": result.method,
        "old_ratio": round(result.old_ratio, 4) if result.old_ratio is not None else None,
        "ratio_std": est.ratio_std if est else None,
        "coulomb_nm": est.coulomb_nm if est else None,
        "viscous_nm_per_rad_s": est.viscous_nm_per_rad_s if est else None,
        "load_torque_nm": est.load_torque_nm if est else None,
        "residual_rel": est.residual_rel if est else None, "notes": list(est.notes) if est else [],
        "samples": len(result.trace.t), "samples_per_s": round(result.samples_per_s, 1),
        "travel_rev": round(result.travel_used_rev, 3) if result.travel_used_rev is not None else None,
        "time_s": round(result.time_used_s, 2), "cycles": result.cycles,
    }


@app.command("inertia")
def inertia(
    ctx: typer.Context,
    method: str = typer.Option("host", "--method", help="host: servotool moves and fits; drive: the drive's own "
                               "identification function."),
    max_speed: float = typer.Option(None, "--max-speed", help="Highest test speed in rpm (default: from --travel)."),
    accel_time: float = typer.Option(None, "--accel-time", help="Ramp time of each move in ms (default: from the "
                                     "link's sampling rate, 100..500 ms)."),
    travel: float = typer.Option(2.0, "--travel", help="Travel limit: range of axis positions in revolutions."),
    direction: str = typer.Option("both", "--direction", help="both (out and back, load torque separated from "
                                  "friction), forward or reverse (only; friction and load torque fitted as one)."),
    repeats: int = typer.Option(None, "--repeats", help="Number of move cycles (default: repeat until the "
                                "estimate is precise, within about 9 s)."),
    rigidity: int = typer.Option(None, "--rigidity", help="Set gains for this rigidity level 1..31."),
    bandwidth: float = typer.Option(None, "--bandwidth", help="Set gains for this speed-loop bandwidth in Hz."),
    no_gains: bool = typer.Option(False, "--no-gains", help="Leave the gains alone (the default unless --rigidity "
                                  "or --bandwidth is given)."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask: move, then write the results."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Identify and show results; write nothing."),
    save_trace: Path = typer.Option(None, "--save-trace", help="Save the sampled speed/torque to this CSV "
                                    "(also when the identification is refused)."),
    step_check: bool = typer.Option(False, "--step-check", help="Measure a speed step (overshoot, settling) "
                                    "before and after; moves out and back inside --travel each time."),
    save: bool = typer.Option(None, "--save/--no-save", help="Store the written ratio and gains in EEPROM (or keep "
                              "them out of it) as the drive allows; default: the drive's current setting."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Identify the load inertia ratio (with friction and gravity), write it, and set matching gains.

    Gains are changed only with --rigidity or --bandwidth.
    """
    _check_options(method, rigidity, bandwidth, no_gains, save_trace)
    step_s = step.step_duration_s(travel) if step_check else None
    with drive(ctx) as d:
        eeprom.check_save_request(d.profile, save)
        preflight.preflight(d, method)
        if method == "host" or step_check:
            confirm_motion(ctx, d, yes, preflight.FEATURE)
        ident = identify.Identifier(d)
        plan, rest = None, None
        if method == "host":
            plan, rest = planning.plan_host_motion(d, max_speed=max_speed, accel_time_ms=accel_time, travel_rev=travel,
                                                 direction=direction, repeats=repeats)
            info(f"motion: {plan.describe()}")
        else:
            info("motion: the drive's own identification (its parameters set torque and travel)")
        if step_s is not None:
            info(f"step check: {step.STEP_SPEED_RPM:g} rpm for {step_s:.2f} s forward and back, before and after")
        if not confirm("Move the axis now?", yes):
            raise typer.Exit(1)
        before = step.step_response(d, step.STEP_SPEED_RPM, step_s) if step_s is not None else None
        try:
            if plan is not None:
                result = ident.run_host(plan, progress=info, rest=rest)
            else:
                result = ident.run_drive(keep=not dry_run)
        except ServoError as exc:   # refused, tripped, travel exceeded, link lost: keep what was measured
            if save_trace:
                ident.trace.save(save_trace)
            if as_json:
                partial = _estimate_json(exc.result) if isinstance(exc, identify.IdentificationRefused) else {}
                emit_json(_clean({"ok": False, "reason": str(exc), **partial,
                                  "ratio": exc.result.new_ratio if isinstance(exc, identify.IdentificationRefused)
                                  else None, "written": False}))
            raise
        if save_trace:
            result.trace.save(save_trace)
        # Where the profile maps no inertia-ratio parameter (SDC) the result is reported, not written.
        entry, raw = gain_writes.ratio_raw(d, result.new_ratio) if d.profile.role("inertia_ratio") else (None, 0)
        want_gains = rigidity is not None or bandwidth is not None
        sugg, changes = gain_writes.gain_changes(d, result.new_ratio, rigidity=rigidity, bandwidth_hz=bandwidth) \
            if want_gains else (None, [])
        est = result.estimate
        if not as_json:
            _show(result, entry, raw, sugg, changes)
        if method == "drive":
            write = False   # the drive stored its own result (or, dry run, it was put back)
            stored = not dry_run
        elif entry is None:
            write = stored = False
        else:
            stored = write = not dry_run and confirm(
                f"Write {entry.code} = {raw * entry.scale:g} {entry.unit}" + (" and the gains" if changes else "")
                + "?", yes)
        gains_written = bool(changes) and not dry_run and (
            write if method == "host" and entry is not None else confirm("Write the gains?", yes))
        persisted = None
        if write or gains_written:
            with eeprom.persistence(d, save) as outcome:
                if write and entry is not None:
                    d.write_verified(entry, raw)
                for c in changes if gains_written else []:
                    d.write_verified(c.entry, c.raw)
            persisted = outcome["persisted"]
        after = step.step_response(d, step.STEP_SPEED_RPM, step_s) if before is not None and stored else None
    if as_json:
        emit_json(_clean({
            "ok": True, **_estimate_json(result), "ratio": round(result.new_ratio, 4),
            "parameter": entry.code if entry else None, "parameter_value": raw * entry.scale if entry else None,
            "written": stored, "persisted": persisted,
            "gains": [{"role": c.role, "code": c.entry.code, "old": c.old, "new": c.new, "unit": c.entry.unit}
                      for c in changes],
            "gains_written": gains_written, "bandwidth_hz": sugg.bandwidth_hz if sugg else None,
            "step_before": vars(before) if before else None, "step_after": vars(after) if after else None,
        }))
        return
    if persisted is False:
        warn(eeprom.ram_only_warning(d.profile))
    what = f"{entry.code} {'written' if stored else 'not written'}" if entry else \
        f"nothing to write: {d.profile.id} maps no inertia-ratio parameter"
    out.print(what
              + (f", gains {'written' if gains_written else 'not written'}" if changes else
                 " (gains unchanged: give --rigidity N or --bandwidth HZ to set them)"), markup=False)
    if est and est.notes:
        for note in est.notes:
            info(note)
    if before is not None:
        out.print(f"step before: {before.describe()}", markup=False)
    if after is not None:
        out.print(f"step after:  {after.describe()}", markup=False)


def _show(result: identify.Result, entry: Any, raw: int, sugg: Any, changes: list[Any]) -> None:
    """The result, shown before asking to write it."""
    est = result.estimate
    old = f"{result.old_ratio:.2f}" if result.old_ratio is not None else "(not a drive parameter)"
    param = f"  ({entry.code} = {raw * entry.scale:g} {entry.unit})" if entry is not None else ""
    out.print(f"load inertia ratio (J_load/J_motor): {old} -> {result.new_ratio:.2f}"
              + (f" ± {est.ratio_std:.2f}" if est else "") + param, markup=False)
    if est:
        travel = f"{result.travel_used_rev:.2f} rev, " if result.travel_used_rev is not None else ""
        out.print(f"friction {est.coulomb_nm:.4f} N·m, viscous {est.viscous_nm_per_rad_s:.2e} N·m·s/rad, "
                  f"load torque {est.load_torque_nm:.4f} N·m, fit residual {est.residual_rel:.1%}; "
                  f"{len(result.trace.t)} samples ({result.samples_per_s:.0f}/s), {travel}"
                  f"{result.time_used_s:.1f} s", markup=False)
    if changes and sugg is not None:
        t = table("Role", "Code", "Current", "Suggested", "Unit",
                  title=f"gains for {sugg.bandwidth_hz:.1f} Hz speed-loop bandwidth"
                        + (f" (rigidity {sugg.rigidity})" if sugg.rigidity else ""))
        for c in changes:
            t.add_row(c.role, c.entry.code, f"{c.old:g}", f"{c.new:g}", c.entry.unit)
        out.print(t)
