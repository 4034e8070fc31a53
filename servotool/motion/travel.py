"""Where the axis is, across the position counter's wrap, and the soft travel limit that holds during motion."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError
from servotool.model.profile import Entry

TYPE_BITS = {"s32": 32, "u32": 32, "s16": 16, "u16": 16}


class TravelLimitHit(DeviceError):
    """The axis reached its soft travel limit: the motor was stopped."""


class AxisPosition:
    """The axis position in revolutions since start(), from a wrapping multi-turn counter (role position_feedback).

    Each reading is taken as the shortest step from the previous one, so the counter may wrap any number of times
    as long as it is read at least once per half its range (256 rev for a 23-bit encoder on a 32-bit counter)."""

    def __init__(self, drive: Drive) -> None:
        self.drive = drive
        self.entry: Entry | None = drive.profile.role("position_feedback")
        motor = drive.profile.motor
        self.counts_per_rev = float(motor.counts_per_rev) if motor is not None else 0.0
        self.modulus = 1 << TYPE_BITS.get(self.entry.type, 32) if self.entry is not None else 0
        self._last: int | None = None
        self._counts = 0

    @property
    def available(self) -> bool:
        return self.entry is not None and self.counts_per_rev > 0 and self.entry.combine == "binary"

    def _raw(self) -> int:
        assert self.entry is not None
        return self.drive.read_entries([self.entry])[0].raw

    def start(self) -> None:
        self._last = self._raw()
        self._counts = 0

    def update(self, raw: int | None = None) -> float:
        """Read (or take) the counter and return the position in revolutions since start()."""
        raw = self._raw() if raw is None else raw
        if self._last is None:
            self._last = raw
        step = (raw - self._last) % self.modulus
        if step >= self.modulus // 2:
            step -= self.modulus
        self._counts += step
        self._last = raw
        return self._counts / self.counts_per_rev


@dataclass(frozen=True)
class TravelLimit:
    """A soft limit: the axis may move at most `rev` revolutions either way from where the motion started."""

    rev: float
    source: str  # where the value came from: --travel, the config file, ...

    def describe(self) -> str:
        return f"travel limit ±{self.rev:g} rev ({self.source})"


class TravelGuard:
    """Checks the axis against its travel limit during motion, allowing for the distance a stop needs."""

    def __init__(self, drive: Drive, limit: TravelLimit | None) -> None:
        self.limit = limit
        self.position = AxisPosition(drive)
        if limit is not None and not (limit.rev > 0):
            raise UsageError("--travel must be a number of revolutions > 0")
        if limit is not None and not self.position.available:
            raise UsageError(
                f"{limit.describe()} needs a position monitor (role position_feedback), which "
                f"profile {drive.profile.id} does not map"
            )
        self.at_rev = 0.0

    def start(self) -> None:
        if self.limit is not None:
            self.position.start()
            self.at_rev = 0.0

    def check(self, direction: int, stop_rev: float) -> None:
        """Raise TravelLimitHit when the axis, moving in `direction`, would pass the limit before it could stop
        (stop_rev: the distance its ramp needs)."""
        if self.limit is None:
            return
        self.at_rev = self.position.update()
        ahead = self.at_rev + direction * stop_rev
        if abs(self.at_rev) >= self.limit.rev or (direction and abs(ahead) >= self.limit.rev and ahead * direction > 0):
            raise TravelLimitHit(f"{self.limit.describe()} reached at {self.at_rev:+.2f} rev: motor stopped")
