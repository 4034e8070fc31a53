"""The picture of a tune: a folder of PNG charts (motion, fit and residual, per-move estimates, step response
before and after, gains) and a report.md that ties them together.

Each chart is built by its own function returning the figure, so tests can check the plotted data before saving.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.report.charts import new_figure, save
from servotool.report.tune_facts import GainRow, gain_rows, move_speeds
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
    reached = move_speeds(result)
    ran = f"; moves reached {reached[0]:.0f}-{reached[1]:.0f} rpm" if reached else ""
    planned = f" (planned up to {result.plan.speed_rpm:.0f} rpm)" if result.plan is not None and reached else ""
    fig.suptitle(f"identification motion: {len(tr.t)} samples at {result.samples_per_s:.0f}/s{ran}{planned}")
    return fig


def fit_figure(result: Result, profile: Profile) -> Figure | None:
    """Where the model was fitted, and only there: each window's average torque as measured and as the model
    explains it, over the torque as logged; below, each window's residual. None without fitted windows."""
    est, motor = result.estimate, profile.motor
    if est is None or motor is None or not est.fitted_windows or len(result.trace.t) < 3:
        return None
    pct = 100.0 / motor.rated_torque_nm
    wins = est.fitted_windows
    fig, (ax, ax_r) = new_figure(2)
    ax.plot(result.trace.t, result.trace.torque, label="torque as logged", color="tab:orange", linewidth=0.6, alpha=0.4)
    centres = [(w.t0 + w.t1) / 2 for w in wins]
    ax.plot(centres, [w.measured_nm * pct for w in wins], "o", color="tab:orange", markersize=2.5,
            label="measured, each window's average")  # fmt: skip
    xs, ys = _runs(wins, [w.model_nm * pct for w in wins])
    ax.plot(xs, ys, color="black", linewidth=1.0, label="model: J·Δω/Δt + friction + load, in the windows fitted")
    ax.set_ylabel("torque [% rated]")
    ax.legend(loc="upper right", fontsize="small")
    resid = [(w.measured_nm - w.model_nm) * pct for w in wins]
    ax_r.plot([(w.t0 + w.t1) / 2 for w in wins], resid, "o", color="tab:red", markersize=2.5, label="measured − model")
    ax_r.axhline(0, color="gray", linewidth=0.8)
    ax_r.set_ylabel("residual [% rated]")
    ax_r.set_xlabel("t [s]")
    for a in (ax, ax_r):
        a.grid(True, alpha=0.3)
    head = "fit" if est.ok else "REFUSED fit"
    fig.suptitle(
        f"{head}: ratio {est.load_ratio:.2f} ± {est.ratio_std:.2f}, window residual {est.residual_rel:.1%} "
        f"({len(wins)} windows; the model is drawn where it was fitted)"
        if est.ok
        else f"{head} ({est.reason.split(':')[0]}): window residual {est.residual_rel:.1%}, {len(wins)} windows"
    )
    return fig


def _runs(wins: Any, values: list[float]) -> tuple[list[float], list[float]]:
    """Window centres and values joined within each run of adjacent windows, broken between runs (NaN), so a line
    is drawn only across windows that were fitted."""
    xs: list[float] = []
    ys: list[float] = []
    for i, (w, v) in enumerate(zip(wins, values, strict=True)):
        if i and abs(wins[i - 1].t1 - w.t0) > 1e-9:
            xs.append(math.nan)
            ys.append(math.nan)
        xs.append((w.t0 + w.t1) / 2)
        ys.append(v)
    return xs, ys


def moves_figure(result: Result) -> Figure | None:
    """Each move's own inertia ratio with its own uncertainty, around the overall estimate; a move that gives no
    ratio of its own is marked along the bottom, not plotted. The axis spans the moves' values and the fit, so one
    very uncertain move does not flatten the others: its error bar runs off the axis, marked with its size."""
    est = result.estimate
    if est is None or not est.moves:
        return None
    moves = est.moves
    fig, (ax,) = new_figure(1, row_in=3.6)
    shown = [(i + 1, m) for i, m in enumerate(moves) if m.fitted]
    n = [i for i, _m in shown]
    ratios = [m.load_ratio for _i, m in shown]
    stds = [m.ratio_std for _i, m in shown]
    fit_ok = est.ok and math.isfinite(est.load_ratio)
    low, high = _move_axis(ratios, stds, est.load_ratio if fit_ok else None, est.ratio_std if fit_ok else 0.0)
    ax.set_ylim(low, high)
    ax.set_xlim(0.4, len(moves) + 0.6)
    if shown:
        ax.errorbar(n, ratios, yerr=stds, fmt="none", ecolor="gray", capsize=3)
        colors = ["tab:blue" if m.direction > 0 else "tab:purple" for _i, m in shown]
        ax.scatter(n, ratios, c=colors, zorder=3, label="per move ± its own 1σ (blue forward, purple reverse)")
    for i, r, s in zip(n, ratios, stds, strict=True):
        if r - s < low or r + s > high:  # the bar runs off the axis: say how long it is
            ax.annotate(f"± {s:.3g}", (i, r), textcoords="offset points", xytext=(5, 4), fontsize="x-small")
    lost = [(i + 1, m) for i, m in enumerate(moves) if not m.fitted]
    if lost:
        ax.scatter(
            [i for i, _m in lost],
            [low + 0.04 * (high - low)] * len(lost),
            marker="x",
            color="tab:red",
            zorder=3,
            label=f"no ratio of its own ({len(lost)}): {lost[0][1].why}" + (" ..." if len(lost) > 1 else ""),
        )
    if fit_ok:
        ax.axhline(est.load_ratio, color="black", label=f"fit {est.load_ratio:.2f}")
        ax.axhspan(
            est.load_ratio - est.ratio_std,
            est.load_ratio + est.ratio_std,
            color="gray",
            alpha=0.2,
            label=f"± {est.ratio_std:.2f} (1σ)",
        )
    spread = float(np.std(ratios, ddof=1)) if len(ratios) > 1 else 0.0
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("move")
    ax.set_ylabel("inertia ratio J_load/J_motor")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, fontsize="small")
    fig.suptitle(
        f"per-move estimates: {len(shown)} of {len(moves)} moves give a ratio of their own, spread (1σ) {spread:.2f}"
    )
    return fig


def _move_axis(ratios: list[float], stds: list[float], fit: float | None, fit_std: float) -> tuple[float, float]:
    """The ratio axis: every move's value and the fit with its band, plus the typical error bar; the longest bars
    may run off it (one bar of ±1400 flattened every other point)."""
    centre = [*ratios, *([fit] if fit is not None else [])]
    if not centre:
        return -1.0, 1.0
    typical = float(np.median(stds)) if stds else 0.0
    low = min(min(centre), (fit - fit_std) if fit is not None else math.inf) - typical
    high = max(max(centre), (fit + fit_std) if fit is not None else -math.inf) + typical
    pad = max(0.08 * (high - low), 0.02 * max(1.0, abs(high)), 1e-3)
    return low - pad, high + pad


def step_figure(before: StepResponse | None, after: StepResponse | None) -> Figure | None:
    """Speed steps before and after, each from the speed at rest at the moment its command went out (t = 0), with
    every sample marked, the time the command took shaded, the 5 % band, the overshoot peak and the settling time;
    the title says how finely they were sampled."""
    steps = [(name, s) for name, s in (("before", before), ("after", after)) if s is not None and s.t_s]
    if not steps:
        return None
    fig, (ax,) = new_figure(1, row_in=3.6)
    target = steps[0][1].target_rpm
    ax.axhspan(0.95 * target, 1.05 * target, color="green", alpha=0.12, label="±5 % band")
    ax.axhline(target, color="green", linewidth=0.8)
    ax.axhline(0, color="gray", linewidth=0.6)
    for (name, s), color in zip(steps, ("tab:red", "tab:blue"), strict=False):
        t_ms = [t * 1000 for t in s.t_s]
        bound = s.overshoot_bound_pct
        said = f"{s.overshoot_pct:.1f} %" + (
            " (not resolved)" if bound is None else f" (≤ {bound:.1f} %)" if bound > s.overshoot_pct + 0.05 else ""
        )
        ax.plot(t_ms, s.speed_rpm, color=color, marker=".", markersize=3, label=f"{name}: overshoot {said}")
        if s.command_ms > 0:
            ax.axvspan(0, s.command_ms, color=color, alpha=0.08)
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
    ax.set_xlabel("t [ms] from the step command (shaded: the command being sent)")
    ax.set_ylabel("speed [rpm]")
    ax.set_xlim(left=-0.02 * max(t * 1000 for _n, s in steps for t in s.t_s))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right", fontsize="small")
    top = max(max(s.speed_rpm) for _n, s in steps)
    ax.set_ylim(top=max(top, 1.05 * target) + 0.12 * abs(target))  # room for the peaks' labels
    first = steps[-1][1]
    fig.suptitle(f"{target:.0f} rpm speed step\n{first.sampling()}", fontsize="medium")
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
