"""A planned JOG: speed, direction, time, ramp, and the bounds servotool prints before moving."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.motion.deadman import DeadManBound
from servotool.motion.travel import TravelLimit


def travel_estimate(speed_rpm: float, seconds: float | None) -> float:
    """How far a timed JOG travels at speed (0 for an interactive one, whose travel the guard watches)."""
    return abs(speed_rpm) / 60.0 * seconds if seconds is not None else 0.0


@dataclass(frozen=True)
class JogPlan:
    speed_rpm: float
    direction: int           # +1 forward, -1 reverse
    seconds: float | None    # None: until stopped
    max_speed_rpm: float
    accel_ms: float | None
    travel_rev: float | None  # estimate for a timed jog
    dead_man: DeadManBound | None = None
    travel_limit: TravelLimit | None = None

    def describe(self) -> str:
        what = "forward" if self.direction > 0 else "reverse"
        more = f" for {self.seconds:g} s (about {self.travel_rev:.2f} rev)" if self.seconds is not None else ""
        ramp = f", ramp {self.accel_ms:g} ms" if self.accel_ms is not None else ""
        limit = f", {self.travel_limit.describe()}" if self.travel_limit is not None else ""
        return f"JOG {what} at {self.speed_rpm:g} rpm{more}{ramp}{limit}"
