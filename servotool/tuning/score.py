"""`tune score`: one standard, bounded test motion, repeated, scored (tuning.fit.score), saved and compared.

The motion is the step check's (tuning.step): a speed step forward at the drive's shortest JOG ramp, stopped, then
a trapezoidal move back as far at a ramp that reaches the speed in a third of the leg; speed and torque read at the
line's full rate. Its travel stays within --travel as the step check's does, with the same dead-man and
protections; it is repeated to measure the spread that the verdict between two scores needs.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.files import write_atomic
from servotool.model.quantity import quantity
from servotool.tuning import step
from servotool.tuning.fit.score import FIGURES, Difference, Figure, LegSamples, Score, combine, compare, score_run
from servotool.tuning.preflight import FEATURE, preflight

DEFAULT_REPEATS = 3
MAX_REPEATS = 20
BACK_RAMP_SHARE = 1.0 / 3.0  # the trapezoid reaches its speed in this share of its leg
SCORE_FORMAT = "servotool score 1"


@dataclass(frozen=True)
class ScoreMotion:
    """The test motion's settings (the same for two scores to compare)."""

    speed_rpm: float
    duration_s: float  # each leg's command
    travel_rev: float

    def describe(self) -> str:
        return (
            f"a {self.speed_rpm:g} rpm step forward and a trapezoidal move back, {self.duration_s * 1000:.0f} ms "
            f"each, within {self.travel_rev:g} rev"
        )


@dataclass
class MeasuredScore:
    motion: ScoreMotion
    score: Score
    runs: list[Score] = field(default_factory=list)
    legs: list[LegSamples] = field(default_factory=list, repr=False)  # the first run's, for charts


def motion_for(travel_rev: float, speed_rpm: float = step.STEP_SPEED_RPM) -> ScoreMotion:
    """The test motion inside travel_rev (a usage error where it cannot fit a step)."""
    if not math.isfinite(speed_rpm) or speed_rpm <= 0:
        raise UsageError("--speed must be a positive number of rpm")
    return ScoreMotion(speed_rpm, step.step_duration_s(travel_rev, speed_rpm), travel_rev)


def planned(drive: Drive, motion: ScoreMotion) -> ScoreMotion:
    """The motion as the step check's plan lets it run (step.plan_step): each leg and what a dead host lets the
    motor run on from its end fit the travel, at a lower speed or in shorter legs where they must."""
    plan = step.plan_step(drive, motion.travel_rev)
    if plan.speed_rpm >= motion.speed_rpm and plan.duration_s >= motion.duration_s:
        return motion
    return ScoreMotion(
        min(motion.speed_rpm, plan.speed_rpm), min(motion.duration_s, plan.duration_s), motion.travel_rev
    )


def check_repeats(repeats: int) -> int:
    if not 1 <= repeats <= MAX_REPEATS:
        raise UsageError(f"--repeats must be 1..{MAX_REPEATS} (2 or more to know the spread)")
    return repeats


def measure(
    drive: Drive,
    motion: ScoreMotion,
    repeats: int = DEFAULT_REPEATS,
    clock: Clock | None = None,
    progress: Callable[[int, Score], None] | None = None,
) -> MeasuredScore:
    """Run the test motion `repeats` times and score it (drive at rest, servo as found afterwards). Where the step
    check's plan (step.plan_step) lowers the speed or shortens the legs to fit a dead host's run-on into the travel,
    the score's motion says so (and a score of another motion is not compared with it)."""
    check_repeats(repeats)
    preflight(drive, "host")
    motion = planned(drive, motion)
    p = drive.profile
    rated = p.motor.rated_speed_rpm if p.motor is not None else 3000.0
    jog_accel = p.need_role("jog_accel", FEATURE)
    speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
    lsb = {"speed": speed_e.scale, "torque": torque_e.scale}
    # the trapezoid's ramp (0 to rated) that reaches the test speed in BACK_RAMP_SHARE of the leg
    back_ramp_ms = max(
        float(jog_accel.min * jog_accel.scale), BACK_RAMP_SHARE * motion.duration_s * 1000.0 * rated / motion.speed_rpm
    )
    runs: list[Score] = []
    first: list[LegSamples] = []
    for n in range(repeats):
        legs, _loop_hz = step.step_legs(
            drive, motion.speed_rpm, motion.duration_s, clock, back_ramp_ms=back_ramp_ms, torque=True
        )
        samples = [LegSamples(g.direction, g.ramp_ms, g.t, g.speed_rpm, g.torque_pct, g.command_ms) for g in legs]
        run = score_run(samples, motion.speed_rpm, rated, lsb)
        runs.append(run)
        first = first or samples
        if progress is not None:
            progress(n + 1, run)
    return MeasuredScore(motion, combine(runs), runs, first)


# ----- JSON: every figure a value with its unit, its spread and its resolution ----------------------------------


def figure_json(name: str, f: Figure) -> dict[str, Any] | None:
    unit = FIGURES[name][0]
    digits = 4 if unit == "rev" else 2
    return quantity(
        _r(f.value, digits),
        unit,
        spread=_r(f.spread, digits) if f.value is not None else None,
        resolution=_r(f.resolution, digits),
    ) or {"value": None, "unit": unit, "resolution": _r(f.resolution, digits)}


def _r(x: float | None, digits: int) -> float | None:
    return None if x is None or not math.isfinite(x) else float(f"{x:.{digits}g}")


def score_json(measured: MeasuredScore, profile_id: str | None = None) -> dict[str, Any]:
    s, m = measured.score, measured.motion
    return {
        "format": SCORE_FORMAT,
        "profile": profile_id,
        "motion": {
            "speed": quantity(m.speed_rpm, "rpm"),
            "leg": quantity(round(m.duration_s * 1000.0), "ms"),
            "travel": quantity(m.travel_rev, "rev"),
        },
        "repeats": s.runs,
        "sample_rate": quantity(round(s.rate_hz, 1), "Hz"),
        "nyquist": quantity(round(s.nyquist_hz, 1), "Hz"),
        "figures": {name: figure_json(name, f) for name, f in s.figures.items()},
    }


def save(measured: MeasuredScore, path: Path, profile_id: str | None = None) -> None:
    write_atomic(path, json.dumps(score_json(measured, profile_id), indent=2) + "\n")


def load(path: Path) -> tuple[Score, ScoreMotion]:
    """A score saved by `tune score --save` (or its --json); a clear error for anything else."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror}") from None
    except (ValueError, UnicodeDecodeError):
        raise UsageError(f"{path}: not a score (not JSON)") from None
    try:
        if data.get("format") != SCORE_FORMAT:
            raise KeyError
        figures = {
            name: Figure(
                None if f is None else f.get("value"),
                float((f or {}).get("spread") or 0.0),
                float((f or {}).get("resolution") or 0.0),
            )
            for name, f in data["figures"].items()
            if name in FIGURES
        }
        m = data["motion"]
        motion = ScoreMotion(float(m["speed"]["value"]), float(m["leg"]["value"]) / 1000.0, float(m["travel"]["value"]))
        rate, nyquist = float(data["sample_rate"]["value"]), float(data["nyquist"]["value"])
        score = Score(figures, int(data["repeats"]), rate, nyquist)
    except (KeyError, TypeError, ValueError, AttributeError):
        raise UsageError(f"{path}: not a score saved by `servotool tune score --save`") from None
    return score, motion


def comparable(a: ScoreMotion, b: ScoreMotion) -> str | None:
    """Why two scores' motions differ (None: the same test motion)."""
    if not math.isclose(a.speed_rpm, b.speed_rpm) or not math.isclose(a.duration_s, b.duration_s, abs_tol=1e-3):
        return f"different test motions ({a.describe()}; {b.describe()})"
    return None


def comparison_json(diffs: list[Difference], overall: str) -> dict[str, Any]:
    return {
        "verdict": overall,
        "figures": {
            d.name: {
                "before": figure_json(d.name, d.before),
                "after": figure_json(d.name, d.after),
                "margin": quantity(_r(d.margin, 4), FIGURES[d.name][0]),
                "verdict": d.verdict,
            }
            for d in diffs
        },
    }


__all__ = ["MeasuredScore", "ScoreMotion", "compare", "comparison_json", "load", "measure", "motion_for", "save"]
