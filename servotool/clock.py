"""Time for motion and measurement: the real clock, or a virtual one the simulator advances."""

from __future__ import annotations

import time
from typing import Protocol


class Timing(Protocol):
    def now(self) -> float: ...
    def sleep(self, seconds: float) -> None: ...


class RealTiming:
    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        time.sleep(max(0.0, seconds))
