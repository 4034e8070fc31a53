"""Numbers behind the tune charts, from the identification's trace and estimate: the speeds the moves reached and
the gains with the room left to their limits (each move's own estimate and the fitted windows come with the
estimate: InertiaEstimate.moves, .fitted_windows)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from servotool.model.codec import raw_to_eng
from servotool.tuning.identify import Result
from servotool.tuning.tune import TuneResult


def move_speeds(result: Result) -> tuple[float, float] | None:
    """(lowest, highest) of the speeds the moves reached (each move's peak over its fitted windows), for saying
    what the moves ran at beside what was planned; None without them."""
    est = result.estimate
    peaks = [m.peak_rpm for m in est.moves if math.isfinite(m.peak_rpm)] if est is not None else []
    return (min(peaks), max(peaks)) if peaks else None


@dataclass(frozen=True)
class GainRow:
    role: str
    code: str
    old: float
    new: float
    unit: str
    low: float | None
    high: float | None

    @property
    def range_text(self) -> str:
        return f"{self.low:g}..{self.high:g}" if self.low is not None and self.high is not None else "?"

    @property
    def margin(self) -> tuple[float, str] | None:
        """The factor the new value may still change by before it meets the nearer limit, and which limit
        (1.0: at the limit, where a computed gain is clamped); None without a range."""
        if self.low is None or self.high is None or self.high <= self.low or self.new <= 0:
            return None
        to_max = self.high / self.new
        to_min = self.new / self.low if self.low > 0 else math.inf
        return (to_min, "min") if to_min < to_max else (to_max, "max")

    @property
    def margin_text(self) -> str:
        m = self.margin
        if m is None:
            return "?"
        factor, limit = m
        return f"at {limit}" if factor <= 1.0 + 1e-9 else f"×{factor:.3g} to {limit}"


def gain_rows(tune: TuneResult) -> list[GainRow]:
    rows = []
    for c in tune.proposal.gain_changes:
        e = c.entry
        low, high = (float(raw_to_eng(e, e.min)), float(raw_to_eng(e, e.max))) if e.max > e.min else (None, None)
        rows.append(GainRow(c.role, e.code, c.old, c.new, e.unit, low, high))
    return rows
