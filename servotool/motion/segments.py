"""The segment route's writes: short relative position moves, each started afresh by a beat (profile dead_man
route segment), so that a dead host leaves at most one segment of motion."""

from __future__ import annotations

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.roles import MotionRoute
from servotool.motion import deadman


class SegmentMoves:
    """Starts the moves of one drive: the displacement (written when it changes) and a start edge."""

    def __init__(self, drive: Drive, route: MotionRoute, feature: str) -> None:
        self.drive = drive
        self.route = route
        self.feature = feature
        dead_man = drive.profile.dead_man
        self.start_bits = dead_man.start_value if dead_man is not None else 1
        motor = drive.profile.motor
        self.rated_rpm = motor.rated_speed_rpm if motor is not None else 3000.0
        self.moving = 0                       # the direction of the running move (0: none or braking)
        self._raw: int | None = None          # the displacement last written
        self._per_rev: float | None = None
        self.start_high = True                # the start bits may be on: a move needs them off first

    def move(self, direction: int, speed_rpm: float, beat_s: float, ramp_ms: float | None) -> bool:
        """A fresh move: in `direction`, long enough to run SEGMENT_BEATS beats then stop; direction 0 brakes a
        running move at the ramp (read as time to rated speed). False when there was nothing to do."""
        if direction:
            rev = direction * deadman.segment_rev(speed_rpm, beat_s, ramp_ms)
        elif self.moving:
            rev = self.moving * deadman.braking_rev(speed_rpm, ramp_ms, self.rated_rpm)
        else:
            return False
        self.moving = direction
        self._start(rev)
        return True

    def _start(self, rev: float) -> None:
        distance = self.route.entries["segment_distance"]
        raw = max(distance.min, min(distance.max, round(rev * self.units_per_rev()))) or (1 if rev > 0 else -1)
        if raw != self._raw:
            self.drive.write_raw(distance, raw)
            self._raw = raw
        start = self.route.entries["segment_start"]
        if self.start_high:
            self.drive.write_raw(start, 1)                  # servo on, start bits off ...
        self.drive.write_raw(start, 1 | self.start_bits)    # ... then on: the edge starts the move
        self.start_high = True

    def forget_distance(self) -> None:
        """The displacement parameter was put back: the next move writes its own again."""
        self._raw = None

    def units_per_rev(self) -> float:
        """Displacement units per motor revolution (role segment_units_per_rev), read once."""
        if self._per_rev is None:
            entry = self.route.entries.get("segment_units_per_rev")
            value = float(raw_to_eng(entry, self.drive.read_entries([entry])[0].raw)) if entry is not None else 0.0
            if value <= 0:
                what = entry.code if entry is not None else "a units-per-revolution setting"
                raise UsageError(f"{self.feature} needs {what} set (the segment displacement's units per motor "
                                 "revolution)")
            self._per_rev = value
        return self._per_rev
