"""The segment route's writes: short relative position moves, each started afresh by a beat (profile dead_man
route segment), so that a dead host leaves at most one segment of motion."""

from __future__ import annotations

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.roles import MotionRoute
from servotool.motion import deadman
from servotool.motion.stop import StoppedElsewhere


class SegmentMoves:
    """Starts the moves of one drive: the displacement (written when it changes) and a start edge."""

    def __init__(self, drive: Drive, route: MotionRoute, feature: str) -> None:
        self.drive = drive
        self.route = route
        self.feature = feature
        dead_man = drive.profile.dead_man
        self.start_bits = dead_man.start_value if dead_man is not None else 1
        self.ramp_rpm = drive.profile.ramp_rpm()  # the speed the ramp time runs up to
        self.moving = 0  # the direction of the running move (0: none or braking)
        self._raw: int | None = None  # the displacement last written
        self._per_rev: float | None = None
        self.start_high = True  # the start bits may be on: a move needs them off first
        self.ends_itself = False  # the running move's own segment stops it (see length_rev)
        self.own_s: float | None = None  # the next fresh move accelerates this long, then stops (once) ...
        self.own_within: float | None = None  # ... its own segment no longer than this (rev; None: unbounded)
        self.single = False  # own moves of any length (the caller's bound is the move: the step check's)

    def move(self, direction: int, speed_rpm: float, beat_s: float, ramp_ms: float | None) -> bool:
        """A fresh move: in `direction`, long enough to run SEGMENT_BEATS beats then stop (or the move's own where
        own_s is set, see length_rev); direction 0 stops a running move at the drive's ramp.
        False when there was nothing to do."""
        own_s, within, self.own_s, self.own_within = self.own_s, self.own_within, None, None
        if direction:
            rev, self.ends_itself = self.length_rev(speed_rpm, beat_s, ramp_ms, own_s, within)
            rev *= direction
        elif self.moving:
            # A stop: the start edges with the shortest displacement the drive takes. On one reading of the firmware
            # the new segment replaces the running one and brakes at the ramp; on the other (the simulator's
            # default) the falling edge brakes the running one and the queued segment adds one displacement unit,
            # where a braking-length segment added the whole braking distance again (identification at 1080 rpm
            # on 2 rev then ran into its travel limit).
            self.ends_itself = False
            rev = self.moving * 0.5 / self.units_per_rev()
        else:
            return False
        self.moving = direction
        self._start(rev, direction)
        return True

    def length_rev(
        self,
        speed_rpm: float,
        beat_s: float,
        ramp_ms: float | None,
        own_s: float | None,
        within_rev: float | None = None,
    ) -> tuple[float, bool]:
        """The length of a fresh move, and whether it is the move's own. A move that accelerates for own_s and then
        stops (identification) is one segment of its own where that is no longer than the dead-man's: the drive
        brakes it at its end by itself, with no re-arm and no stop command (three writes a move on IS620P).
        within_rev: the own segment no longer than this (the room the caller's travel band leaves: the drive then
        brakes it short of the band's edge however late the host looks again), down to nothing."""
        bounded = deadman.segment_rev(speed_rpm, beat_s, ramp_ms, self.ramp_rpm)
        if own_s is None or ramp_ms is None or ramp_ms < 0:
            return bounded, False
        to_speed_s = ramp_ms / 1000.0 * abs(speed_rpm) / self.ramp_rpm
        # up for own_s, down as long (a ramp of 0: at speed for own_s)
        own = abs(speed_rpm) / 60.0 * own_s * (min(1.0, own_s / to_speed_s) if to_speed_s > 0 else 1.0)
        if within_rev is not None and within_rev < own:
            # short of it by half a displacement unit: rounded, the segment still ends within it
            own = max(0.0, within_rev - 0.5 / self.units_per_rev())
        return (own, True) if own <= bounded or self.single else (bounded, False)

    def distance_raw(
        self,
        direction: int,
        speed_rpm: float,
        beat_s: float,
        ramp_ms: float | None,
        own_s: float | None = None,
        within_rev: float | None = None,
    ) -> int:
        """The displacement (raw) a fresh move in `direction` writes (see move)."""
        return self._raw_of(direction * self.length_rev(speed_rpm, beat_s, ramp_ms, own_s, within_rev)[0], direction)

    def distance_written(self, raw: int) -> None:
        """The displacement was written with other settings (Jogger.start): the move need not write it again."""
        self._raw = raw

    def written_distance(self) -> int | None:
        """The displacement last written (None: unknown)."""
        return self._raw

    def _raw_of(self, rev: float, direction: int = 0) -> int:
        """rev in displacement units, at least one (in direction where rev rounds to nothing)."""
        distance = self.route.entries["segment_distance"]
        raw = max(distance.min, min(distance.max, round(rev * self.units_per_rev())))
        return raw or (1 if (rev or direction) > 0 else -1)

    def _start(self, rev: float, direction: int) -> None:
        distance = self.route.entries["segment_distance"]
        raw = self._raw_of(rev, direction)
        if raw != self._raw:
            self.drive.write_raw(distance, raw)
            self._raw = raw
        start = self.route.entries["segment_start"]
        if self.start_high:
            # A re-arm, the servo on since the first move: where it reads off, something switched it off
            # ('servotool stop'), and the S-ON this write carries would switch it back on.
            if not self.drive.read_entries([start])[0].raw & 1:
                raise StoppedElsewhere(
                    f"{start.code} reads the servo off: the drive was stopped from elsewhere ('servotool stop'?)"
                )
            self.drive.write_raw(start, 1)  # servo on, start bits off ...
        self.drive.write_raw(start, 1 | self.start_bits)  # ... then on: the edge starts the move
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
                raise UsageError(
                    f"{self.feature} needs {what} set (the segment displacement's units per motor revolution)"
                )
            self._per_rev = value
        return self._per_rev
