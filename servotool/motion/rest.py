"""When a stopped axis is at rest: its speed inside a band on end, not for one reading.

An underdamped speed loop swings through zero after a stop: one reading near zero is what it shows on the way
through (DSX7E with a load of 6 and Pn101 25 Hz: -59, then +123 rpm 20 ms later; the identification took the
reading in between for rest, returned, and the axis was still turning at 30-40 rpm as a plan read its speed).
"""

from __future__ import annotations

# The speed stays inside the band at least this long, over at least two readings: a swing through zero at the
# loop's usual rates (thousands of rpm/s) crosses a band of a few rpm in a few ms.
SETTLE_S = 0.02
STOPPED_RPM = 3.0  # the band of a stop that knows no speed noise (JOG, step check)


class RestWatch:
    """Feed it each speed reading with its time; at_rest once the speed has stayed inside the band long enough."""

    def __init__(self, band_rpm: float, settle_s: float = SETTLE_S) -> None:
        self.band_rpm = band_rpm
        self.settle_s = settle_s
        self._since: float | None = None
        self._count = 0

    def at_rest(self, now: float, speed_rpm: float) -> bool:
        """Whether the axis is at rest after this reading."""
        if abs(speed_rpm) >= self.band_rpm:
            self._since, self._count = None, 0
            return False
        if self._since is None:
            self._since = now
        self._count += 1
        return self._count >= 2 and now - self._since >= self.settle_s
