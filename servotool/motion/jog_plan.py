"""A planned JOG: speed, direction, time, ramp, and the bounds servotool prints before moving."""

from __future__ import annotations

import math
from dataclasses import dataclass

from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.motion.deadman import DeadManBound
from servotool.motion.travel import TravelLimit


def travel_estimate(speed_rpm: float, seconds: float | None) -> float:
    """How far a timed JOG travels at speed (0 for an interactive one, whose travel the guard watches)."""
    return abs(speed_rpm) / 60.0 * seconds if seconds is not None else 0.0


def checked_travel(
    speed_rpm: float, seconds: float | None, limit_rev: float | None = None, limit_name: str = ""
) -> float:
    """The travel estimate of a JOG request, its speed and time checked; over limit_rev (worded limit_name, by
    default '--max-travel limit N rev') is refused."""
    if speed_rpm == 0 or not math.isfinite(speed_rpm):
        raise UsageError("--speed must be a non-zero number (its sign gives the direction)")
    if seconds is not None and not (math.isfinite(seconds) and seconds > 0):
        raise UsageError("--time must be a number > 0")
    estimate = travel_estimate(speed_rpm, seconds)
    if limit_rev is not None and estimate > limit_rev:
        raise UsageError(
            f"a {seconds:g} s JOG at {abs(speed_rpm):g} rpm travels about {estimate:.2f} rev, over "
            f"the {limit_name or f'--max-travel limit {limit_rev:g} rev'}"
        )
    return estimate


def ramp_words(profile: Profile, accel_ms: float | None) -> str:
    """The ramp in the drive's own terms: its entry, its time, and the speed that time runs up to where the profile
    says (dead_man.ramp_reference_rpm: 0 for the rated speed); '' without a ramp entry."""
    entry = profile.role("jog_accel")
    if entry is None or accel_ms is None:
        return ""
    # Read defensively: the reference is a dead_man key of issue 29's stop work, absent from older profiles.
    reference = getattr(profile.dead_man, "ramp_reference_rpm", None)
    if reference is None:
        return f"ramp {entry.code} = {accel_ms:g} ms (the speed it runs up to is not in the profile)"
    rated = profile.motor.rated_speed_rpm if profile.motor is not None else None
    to = f"{reference:g} rpm" if reference else "the rated speed" + (f" ({rated:g} rpm)" if rated else "")
    return f"ramp {entry.code} = {accel_ms:g} ms from 0 to {to}"


@dataclass(frozen=True)
class JogPlan:
    speed_rpm: float
    direction: int  # +1 forward, -1 reverse
    seconds: float | None  # None: until stopped
    max_speed_rpm: float
    accel_ms: float | None
    travel_rev: float | None  # estimate for a timed jog
    dead_man: DeadManBound | None = None
    travel_limit: TravelLimit | None = None
    ramp: str = ""  # ramp_words: the ramp in the drive's own terms

    def describe(self) -> str:
        what = "forward" if self.direction > 0 else "reverse"
        more = f" for {self.seconds:g} s (about {self.travel_rev:.2f} rev)" if self.seconds is not None else ""
        ramp = f", {self.ramp}" if self.ramp else f", ramp {self.accel_ms:g} ms" if self.accel_ms is not None else ""
        limit = f", {self.travel_limit.describe()}" if self.travel_limit is not None else ""
        return f"JOG {what} at {self.speed_rpm:g} rpm{more}{ramp}{limit}"
