"""report.md of a tune: what was measured, what it means, and the charts beside it."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from servotool.model.profile import Profile
from servotool.report.tune_facts import GainRow, move_speeds
from servotool.tuning.fit import MoveEstimate
from servotool.tuning.identify import Result
from servotool.tuning.tune import TuneResult


def _f(x: float | None, fmt: str = ".3g") -> str:
    return "n/a" if x is None or not math.isfinite(x) else format(x, fmt)


def report_markdown(
    result: Result,
    profile: Profile,
    tune: TuneResult | None,
    rows: list[GainRow],
    charts: list[tuple[str, str]],
    reason: str = "",
) -> str:
    est = result.estimate
    old = f"{result.old_ratio:.2f}" if result.old_ratio is not None else "not a drive parameter"
    lines = [f"# Inertia tune: {profile.model} (profile {profile.id})", ""]
    lines += [f"**Refused:** {reason}", ""] if reason else []
    found = (  # a refused result is no result: no ratio is given for it
        "none: the identification was refused"
        if reason
        else f"{result.new_ratio:.2f}" + (f" ± {est.ratio_std:.2f} (1σ)" if est else "")
    )
    lines += [
        "| | |",
        "|---|---|",
        f"| method | {result.method} |",
        f"| load inertia ratio (J_load/J_motor) | {old} → {found} |",
    ]
    if est is not None:
        lines += [
            f"| Coulomb friction | {_f(est.coulomb_nm, '.4f')} N·m |",
            f"| viscous friction | {_f(est.viscous_nm_per_rad_s, '.2e')} N·m·s/rad |",
            f"| load torque | {_f(est.load_torque_nm, '.4f')} N·m |",
            f"| fit residual | {_f(est.residual_rel, '.1%')} of the torque integrals |",
            f"| windows / excitation | {est.n_windows} / {_f(est.excitation, '.1f')}× the speed noise |",
        ]
    travel = f"{result.travel_used_rev:.2f} rev" if result.travel_used_rev is not None else "n/a"
    reached = move_speeds(result)
    planned = f"planned up to {result.plan.speed_rpm:.0f} rpm" if result.plan is not None else ""
    speeds = (
        f"reached {reached[0]:.0f}-{reached[1]:.0f} rpm" + (f" ({planned})" if planned else "")
        if reached
        else planned or "n/a"
    )
    lines += [
        f"| samples | {len(result.trace.t)} at {result.samples_per_s:.0f}/s, {result.cycles} cycles, "
        f"{result.time_used_s:.1f} s, travel {travel} |",
        f"| move speeds | {speeds} |",
        "",
    ]
    if est is not None and est.moves:
        lines += _moves_lines(est.moves)
    if tune is not None:
        written = "written" if tune.ratio_stored else "not written"
        gains = ("gains written" if tune.gains_written else "gains not written") if rows else "gains unchanged"
        saved = {True: "stored in EEPROM", False: "in RAM only (lost at power-off)", None: ""}[tune.persisted]
        lines += [f"Outcome: ratio {written}, {gains}" + (f", {saved}" if saved else "") + ".", ""]
        for name, s in (("before", tune.step_before), ("after", tune.step_after)):
            if s is not None:
                lines.append(f"- step {name}: {s.describe()}")
        if tune.step_before is not None:
            lines.append("")
    if rows:
        lines += ["| role | code | current | new | unit | range | margin |", "|---|---|---|---|---|---|---|"]
        lines += [
            f"| {r.role} | {r.code} | {r.old:g} | {r.new:g} | {r.unit} | {r.range_text} | {r.margin_text} |"
            for r in rows
        ]
        lines.append("")
    for name, heading in charts:
        lines += [f"## {heading}", "", f"![{heading}]({name})", ""]
    return "\n".join(lines)


def _moves_lines(moves: Sequence[MoveEstimate]) -> list[str]:
    """Each move's own ratio and uncertainty; a move that gives none, with why."""
    fitted = [m for m in moves if m.fitted]
    ratios = [m.load_ratio for m in fitted]
    spread = float(np.std(ratios, ddof=1)) if len(ratios) > 1 else 0.0
    head = (
        f"Per move (friction and load held at the fit, each with its own 1σ): {len(fitted)} of {len(moves)} moves "
        + (f"give ratios {min(ratios):.2f}..{max(ratios):.2f}, spread {spread:.2f} (1σ)." if ratios else "give none.")
    )
    lines = [head, "", "| move | direction | peak speed | ratio |", "|---|---|---|---|"]
    for i, m in enumerate(moves, 1):
        ratio = f"{m.load_ratio:.2f} ± {m.ratio_std:.2f}" if m.fitted else f"none ({m.why})"
        lines.append(f"| {i} | {'forward' if m.direction > 0 else 'reverse'} | {_f(m.peak_rpm, '.0f')} rpm | {ratio} |")
    return [*lines, ""]
