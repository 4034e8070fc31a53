"""The evidence of a drive function's trial (`tune friction|notch --report DIR`): the test motion before and after
on the same axes, and the score table with the verdicts, as report.md."""

from __future__ import annotations

from pathlib import Path

from servotool.errors import UsageError
from servotool.files import write_atomic
from servotool.report.charts import new_figure, save
from servotool.tuning.drive_functions import FunctionTrial
from servotool.tuning.fit.score import FIGURES


def write(folder: Path, trial: FunctionTrial) -> list[Path]:
    """response.png (speed and torque of the first run's legs, before and after, same axes) and report.md."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UsageError(f"cannot write the report to {folder}: {exc.strerror}") from None
    written = [_chart(folder / "response.png", trial)] if trial.before is not None and trial.before.legs else []
    lines = [f"# tune {trial.function}", "", f"**{'KEPT' if trial.kept else 'NOT KEPT'}**: {trial.reason}", ""]
    if trial.before is not None:
        lines += [f"Test motion: {trial.before.motion.describe()}; {trial.before.score.runs} runs before", ""]
    if trial.changes:
        lines += ["| entry | before | tried | what |", "|---|---|---|---|"]
        lines += [f"| {c.entry.code} | {c.old_value:g} | {c.new_value:g} | {c.why} |" for c in trial.changes]
        lines.append("")
    if trial.differences:
        lines += ["| figure | before | after | must differ by | verdict |", "|---|---|---|---|---|"]
        for d in trial.differences:
            unit = FIGURES[d.name][0]

            def text(v: float | None, spread: float, unit: str = unit) -> str:
                return "-" if v is None else f"{v:.4g} ± {spread:.2g} {unit}"

            lines.append(
                f"| {d.name} | {text(d.before.value, d.before.spread)} | {text(d.after.value, d.after.spread)} "
                f"| {d.margin:.3g} {unit} | {d.verdict} |"
            )
        lines.append("")
    if trial.held:
        lines.append("Read back: " + ", ".join(f"{k} = {v:g}" for k, v in trial.held.items()))
    path = folder / "report.md"
    try:
        write_atomic(path, "\n".join(lines) + "\n")
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror}") from None
    return [*written, path]


def _chart(path: Path, trial: FunctionTrial) -> Path:
    fig, (ax_v, ax_q) = new_figure(2)
    for label, measured, style, colour in (("before", trial.before, "-", "C0"), ("after", trial.after, "--", "C1")):
        if measured is None or not measured.legs:
            continue
        offset = 0.0
        for n, leg in enumerate(measured.legs):
            t = [offset + x for x in leg.t]
            name = label if n == 0 else None
            ax_v.plot(t, leg.speed_rpm, style, color=colour, label=name, linewidth=1.2)
            if leg.torque_pct:
                ax_q.plot(t, leg.torque_pct, style, color=colour, label=name, linewidth=1.2)
            offset = t[-1] + 0.05
    ax_v.set_ylabel("speed [rpm]")
    ax_q.set_ylabel("torque [%]")
    ax_q.set_xlabel("time from each leg's command [s] (legs side by side)")
    for ax in (ax_v, ax_q):
        ax.grid(True, alpha=0.3)
        ax.legend(loc="upper right", fontsize="small")
    fig.suptitle(f"tune {trial.function}: the test motion before and after ({trial.verdict})")
    return save(fig, path)
