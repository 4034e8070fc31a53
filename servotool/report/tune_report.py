"""The picture of a tune: a folder of PNG charts (motion, fit and residual, per-move estimates, step response
before and after, gains) and a report.md that ties them together.

Each chart is built by its own function returning the figure, so tests can check the plotted data before saving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.report.charts import new_figure, save
from servotool.report.tune_facts import GainRow, gain_rows, model_torque_pct
from servotool.tuning.identify import Result
from servotool.tuning.step import StepResponse
from servotool.tuning.tune import TuneResult

if TYPE_CHECKING:
    from matplotlib.figure import Figure


@dataclass(frozen=True)
class TuneReport:
    folder: Path
    files: list[Path]  # the PNGs and report.md, in the order report.md shows them


def check_folder(folder: Path) -> None:
    """Refuse a report folder that cannot be made or written, and a missing matplotlib, before anything moves."""
    from servotool.report.charts import need_matplotlib

    need_matplotlib()
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"cannot write the report to {folder}: it is a file")
    existing = next((p for p in folder.parents if p.exists()), Path("."))
    if not existing.is_dir():
        raise UsageError(f"cannot write the report to {folder}: {existing} is not a folder")


def motion_figure(result: Result) -> Figure:
    """Speed, torque and travel against time, as sampled during the identification."""
    tr = result.trace
    fig, (ax_v, ax_q, ax_x) = new_figure(3)
    ax_v.plot(tr.t, tr.speed, label="speed", color="tab:blue")
    ax_v.set_ylabel("speed [rpm]")
    ax_q.plot(tr.t, tr.torque, label="torque", color="tab:orange")
    ax_q.set_ylabel("torque [% rated]")
    pos = [(t, x) for t, x in zip(tr.t, tr.position, strict=True) if x is not None]
    if pos:
        x0 = pos[0][1]
        ax_x.plot(
            [p[0] for p in pos], [p[1] - x0 for p in pos], label="travel", color="tab:green", marker=".", markersize=3
        )
    else:
        ax_x.text(0.5, 0.5, "no position feedback in this profile", ha="center", transform=ax_x.transAxes)
    if result.plan is not None:
        for sign in (1, -1):
            ax_x.axhline(sign * result.plan.travel_limit_rev, color="red", linestyle=":", linewidth=1)
    ax_x.set_ylabel("travel [rev]")
    ax_x.set_xlabel("t [s]")
    for ax in (ax_v, ax_q, ax_x):
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"identification motion: {len(tr.t)} samples at {result.samples_per_s:.0f}/s")
    return fig


def fit_figure(result: Result, profile: Profile) -> Figure | None:
    """Measured torque against the fitted model's, and the residual; None without an estimate."""
    est, motor = result.estimate, profile.motor
    if est is None or motor is None or not math.isfinite(est.j_total_kgm2) or len(result.trace.t) < 3:
        return None
    t = np.asarray(result.trace.t)
    measured = np.asarray(result.trace.torque)
    model = model_torque_pct(result, motor.rated_torque_nm)
    fig, (ax, ax_r) = new_figure(2)
    ax.plot(t, measured, label="measured", color="tab:orange", linewidth=1)
    ax.plot(t, model, label="model: J·dω/dt + friction + load", color="black", linewidth=1, linestyle="--")
    ax.set_ylabel("torque [% rated]")
    ax.legend(loc="upper right", fontsize="small")
    resid = measured - model
    ax_r.plot(t, resid, label="measured − model", color="tab:red", linewidth=1)
    ax_r.axhline(0, color="gray", linewidth=0.8)
    ax_r.set_ylabel("residual [% rated]")
    ax_r.set_xlabel("t [s]")
    for a in (ax, ax_r):
        a.grid(True, alpha=0.3)
    fig.suptitle(f"fit: ratio {est.load_ratio:.2f} ± {est.ratio_std:.2f}, window residual {est.residual_rel:.1%}")
    return fig


def moves_figure(result: Result) -> Figure | None:
    """Each move's own inertia ratio (friction and load held at the fit) around the overall estimate."""
    est = result.estimate
    if est is None or not est.moves:
        return None
    moves = est.moves
    fig, (ax,) = new_figure(1, row_in=3.6)
    n = list(range(1, len(moves) + 1))
    ratios = [m.load_ratio for m in moves]
    colors = ["tab:blue" if m.direction > 0 else "tab:purple" for m in moves]
    ax.errorbar(n, ratios, yerr=[m.ratio_std for m in moves], fmt="none", ecolor="gray", capsize=3)
    ax.scatter(n, ratios, c=colors, zorder=3, label="per move (blue forward, purple reverse)")
    ax.plot(n, ratios, color="gray", linewidth=0.6, alpha=0.6)
    ax.axhline(est.load_ratio, color="black", label=f"fit {est.load_ratio:.2f}")
    ax.axhspan(
        est.load_ratio - est.ratio_std,
        est.load_ratio + est.ratio_std,
        color="gray",
        alpha=0.2,
        label=f"± {est.ratio_std:.2f} (1σ)",
    )
    spread = float(np.std(ratios, ddof=1)) if len(ratios) > 1 else 0.0
    ax.set_xlabel("move")
    ax.set_ylabel("inertia ratio J_load/J_motor")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize="small")
    fig.suptitle(f"per-move estimates: {len(moves)} moves, spread (1σ) {spread:.2f}")
    return fig


def step_figure(before: StepResponse | None, after: StepResponse | None) -> Figure | None:
    """Speed steps before and after, with the 5 % band, the overshoot peak and the settling time marked."""
    steps = [(name, s) for name, s in (("before", before), ("after", after)) if s is not None and s.t_s]
    if not steps:
        return None
    fig, (ax,) = new_figure(1, row_in=3.6)
    target = steps[0][1].target_rpm
    ax.axhspan(0.95 * target, 1.05 * target, color="green", alpha=0.12, label="±5 % band")
    ax.axhline(target, color="green", linewidth=0.8)
    for (name, s), color in zip(steps, ("tab:red", "tab:blue"), strict=False):
        t_ms = [t * 1000 for t in s.t_s]
        ax.plot(t_ms, s.speed_rpm, color=color, label=f"{name}: overshoot {s.overshoot_pct:.1f} %")
        peak = int(np.argmax(s.speed_rpm))
        ax.annotate(
            f"{s.overshoot_pct:.1f} %",
            (t_ms[peak], s.speed_rpm[peak]),
            textcoords="offset points",
            xytext=(4, 6),
            color=color,
            fontsize="small",
        )
        ax.plot([t_ms[peak]], [s.speed_rpm[peak]], marker="v", color=color)
        if s.settling_ms is not None:
            ax.axvline(s.settling_ms, color=color, linestyle=":", label=f"{name}: settled at {s.settling_ms:.0f} ms")
    ax.set_xlabel("t [ms]")
    ax.set_ylabel("speed [rpm]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")
    fig.suptitle(f"{target:.0f} rpm speed step")
    return fig


def gains_figure(rows: list[GainRow], title: str) -> Figure | None:
    """The gains table as a picture: current, new, the entry's range and the room left to its nearer limit."""
    if not rows:
        return None
    fig, (ax,) = new_figure(1, row_in=0.3 * len(rows), sharex=False)
    ax.axis("off")
    cells = [[r.role, r.code, f"{r.old:g}", f"{r.new:g}", r.unit, r.range_text, r.margin_text] for r in rows]
    tab = ax.table(
        cellText=cells, colLabels=["role", "code", "current", "new", "unit", "range", "margin"], loc="center"
    )
    tab.auto_set_font_size(False)
    tab.set_fontsize(9)
    tab.auto_set_column_width(list(range(7)))
    fig.suptitle(title)
    return fig


def write_tune_report(
    folder: Path, result: Result, profile: Profile, tune: TuneResult | None = None, reason: str = ""
) -> TuneReport:
    """Write the charts and report.md into folder (made if needed); reason: why the result was refused, if it was."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot make {folder}: {exc.strerror or exc}") from None
    rows = gain_rows(tune) if tune is not None else []
    sugg = tune.proposal.suggestion if tune is not None else None
    gains_title = f"gains for {sugg.bandwidth_hz:.1f} Hz speed-loop bandwidth" if sugg else "gains"
    charts = [
        ("motion.png", "Motion", motion_figure(result) if result.trace.t else None),
        ("fit.png", "Fit and residual", fit_figure(result, profile)),
        ("moves.png", "Per-move estimates", moves_figure(result)),
        ("step.png", "Step response", step_figure(tune.step_before, tune.step_after) if tune else None),
        ("gains.png", "Gains", gains_figure(rows, gains_title)),
    ]
    files, shown = [], []
    for name, heading, fig in charts:
        if fig is not None:
            files.append(save(fig, folder / name))
            shown.append((name, heading))
    from servotool.report.tune_markdown import report_markdown

    md = folder / "report.md"
    try:
        md.write_text(report_markdown(result, profile, tune, rows, shown, reason), encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot write {md}: {exc.strerror or exc}") from None
    return TuneReport(folder, [*files, md])
