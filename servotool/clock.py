"""The one clock protocol: the real clock, or a virtual one that moves only when told (tests, benchmarks).

Motion, measurement and the simulated plant all take a Clock, so a run on virtual time is the same code as a run
on a real line.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime
from typing import Protocol


class Clock(Protocol):
    def now(self) -> float:
        """Monotonic seconds."""
        ...

    def wall(self) -> float:
        """Wall-clock seconds, to hand a simulated drive's state over to another process."""
        ...

    def sleep(self, seconds: float) -> None: ...


class RealClock:
    def now(self) -> float:
        return time.monotonic()

    def wall(self) -> float:
        return time.time()

    def sleep(self, seconds: float) -> None:
        time.sleep(max(0.0, seconds))


class VirtualClock:
    """A clock that moves only when told: deterministic tests and fast benchmarks.

    computing_s: how long a computation beside a motion (KeepAlive.while_computing: a fit between moves) takes on this
    host; 0 (the default) as if instant. On a real host such a fit takes tens of ms, about 100 ms for the two-mass scan
    of a long log, and the samples pause meanwhile: a test or bench sets it to see that pause."""

    def __init__(self, start: float = 0.0, computing_s: float = 0.0) -> None:
        self.t = start
        self.computing_s = computing_s

    def now(self) -> float:
        return self.t

    def wall(self) -> float:
        return self.t  # drives sharing one virtual clock share its time

    def sleep(self, seconds: float) -> None:
        self.advance(max(0.0, seconds))

    def advance(self, dt: float) -> float:
        self.t += dt
        return self.t


def utc_now(clock: Clock | None = None) -> datetime:
    """The clock's wall time as an aware UTC datetime (for time stamps in files and reports)."""
    return datetime.fromtimestamp((clock or RealClock()).wall(), UTC)
