"""`servotool tune inertia`: identify the load inertia ratio, set it, suggest and set gains."""

from __future__ import annotations

from pathlib import Path

import typer

from servotool.cli.common import confirm, drive
from servotool.cli.jog import confirm_motion
from servotool.cli.render import emit_json, info, out, table
from servotool.errors import UsageError
from servotool.tuning import wizard

app = typer.Typer(no_args_is_help=True, help="Identify load inertia and set gains.")


@app.command("inertia")
def inertia(
    ctx: typer.Context,
    method: str = typer.Option("host", "--method", help="host: servotool moves and fits; drive: the drive's own "
                               "identification function."),
    max_speed: float = typer.Option(None, "--max-speed", help="Highest test speed in rpm (default: from --travel)."),
    accel_time: float = typer.Option(200.0, "--accel-time", help="Ramp time of each move in ms."),
    travel: float = typer.Option(2.0, "--travel", help="Travel limit: revolutions of axis movement in all."),
    direction: str = typer.Option("both", "--direction", help="both, forward or reverse."),
    repeats: int = typer.Option(3, "--repeats", help="Number of move cycles."),
    rigidity: int = typer.Option(None, "--rigidity", help="Suggest gains for this rigidity level 1..31."),
    bandwidth: float = typer.Option(None, "--bandwidth", help="Suggest gains for this speed-loop bandwidth in Hz."),
    no_gains: bool = typer.Option(False, "--no-gains", help="Only identify and set the inertia ratio."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask: move, then write the results."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Identify and show results; write nothing."),
    save_trace: Path = typer.Option(None, "--save-trace", help="Save the sampled speed/torque to this CSV."),
    step_check: bool = typer.Option(False, "--step-check", help="Measure a speed step (overshoot, settling) "
                                    "before and after; moves the axis about 1 more revolution each time."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable result."),
) -> None:
    """Identify the load inertia ratio (with friction and gravity), write it, and set matching gains."""
    if method not in ("host", "drive"):
        raise UsageError("--method must be host or drive")
    if rigidity is not None and bandwidth is not None:
        raise UsageError("give --rigidity or --bandwidth, not both")
    with drive(ctx) as d:
        wizard.preflight(d, method)
        if method == "host" or step_check:
            confirm_motion(ctx, d, yes, wizard.FEATURE)
        ident = wizard.Identifier(d)
        step_speed = 200.0
        before = wizard.step_response(d, step_speed) if step_check and confirm("Run the step check?", yes) \
            else None
        if method == "host":
            plan = wizard.plan_motion(d.profile, max_speed=max_speed, accel_time_ms=accel_time, travel_rev=travel,
                                      direction=direction, repeats=repeats)
            info(f"motion: {plan.describe()}")
            if not confirm("Move the axis now?", yes):
                raise typer.Exit(1)
            result = ident.run_host(plan, progress=info)
        else:
            info("motion: the drive's own identification (its parameters set torque and travel)")
            if not confirm("Start the drive's identification now?", yes):
                raise typer.Exit(1)
            result = ident.run_drive()
        if save_trace:
            result.trace.save(save_trace)
        entry, raw = wizard.ratio_raw(d, result.new_ratio)
        sugg, changes = (None, []) if no_gains else wizard.gain_changes(d, result.new_ratio, rigidity=rigidity,
                                                                        bandwidth_hz=bandwidth)
        write = not dry_run and (method == "host") and confirm(
            f"Write {entry.code} = {raw * entry.scale:g} {entry.unit}"
            + (" and the gains" if changes else "") + "?", yes)
        if write:
            d.write_verified(entry, raw)
            for c in changes:
                d.write_verified(c.entry, c.raw)
        elif method == "drive" and not dry_run:
            write = True  # the drive stored its result itself
        after = wizard.step_response(d, step_speed) if before is not None and write else None
    est = result.estimate
    if as_json:
        emit_json({
            "method": result.method, "old_ratio": round(result.old_ratio, 4), "ratio": round(result.new_ratio, 4),
            "ratio_std": round(est.ratio_std, 4) if est else None,
            "coulomb_nm": est.coulomb_nm if est else None, "viscous_nm_per_rad_s": est.viscous_nm_per_rad_s if est
            else None, "load_torque_nm": est.load_torque_nm if est else None,
            "residual_rel": est.residual_rel if est else None, "samples": len(result.trace.t),
            "samples_per_s": round(result.samples_per_s, 1), "travel_rev": round(result.travel_used_rev, 3),
            "time_s": round(result.time_used_s, 2), "parameter": entry.code, "parameter_value": raw * entry.scale,
            "written": write,
            "gains": [{"role": c.role, "code": c.entry.code, "old": c.old, "new": c.new, "unit": c.entry.unit}
                      for c in changes],
            "bandwidth_hz": sugg.bandwidth_hz if sugg else None,
            "step_before": vars(before) if before else None, "step_after": vars(after) if after else None,
        })
        return
    out.print(f"load inertia ratio (J_load/J_motor): {result.old_ratio:.2f} -> {result.new_ratio:.2f}"
              + (f" ± {est.ratio_std:.2f}" if est else ""), markup=False)
    if est:
        out.print(f"friction {est.coulomb_nm:.4f} N·m, viscous {est.viscous_nm_per_rad_s:.2e} N·m·s/rad, "
                  f"load torque {est.load_torque_nm:.4f} N·m, fit residual {est.residual_rel:.1%}; "
                  f"{len(result.trace.t)} samples ({result.samples_per_s:.0f}/s), {result.travel_used_rev:.2f} rev, "
                  f"{result.time_used_s:.1f} s", markup=False)
    out.print(f"{entry.code} = {raw * entry.scale:g} {entry.unit} {'written' if write else 'not written'}",
              markup=False)
    if changes and sugg is not None:
        t = table("Role", "Code", "Current", "Suggested", "Unit",
                  title=f"gains for {sugg.bandwidth_hz:.1f} Hz speed-loop bandwidth"
                        + (f" (rigidity {sugg.rigidity})" if sugg.rigidity else ""))
        for c in changes:
            t.add_row(c.role, c.entry.code, f"{c.old:g}", f"{c.new:g}", c.entry.unit)
        out.print(t)
    if before is not None:
        out.print(f"step before: {before.describe()}", markup=False)
    if after is not None:
        out.print(f"step after:  {after.describe()}", markup=False)
