"""When a stopped axis is at rest: its speed inside a band on end, not for one reading, and its mean speed near zero.

An underdamped speed loop swings through zero after a stop: one reading near zero is what it shows on the way
through (DSX7E with a load of 6 and Pn101 25 Hz: -59, then +123 rpm 20 ms later; the identification took the
reading in between for rest, returned, and the axis was still turning at 30-40 rpm as a plan read its speed).
A noisy reading's band is wide, so the band alone is no proof either: a gravity axis held at 38 rpm sat inside a
band of four noises (41 rpm) and was let go. The mean of enough readings tells a slow turn from noise.
"""

from __future__ import annotations

import math
from collections import deque

# The speed stays inside the band at least this long, over at least two readings: a swing through zero at the
# loop's usual rates (thousands of rpm/s) crosses a band of a few rpm in a few ms.
SETTLE_S = 0.02
STOPPED_RPM = 3.0  # the band of a stop that knows no speed noise (JOG, step check)
BAND_SIGMAS = 4.0  # a noisy reading's band is this many of its noises (one reading at rest stays inside it)
REST_MEAN_RPM = 10.0  # at rest, the mean speed of the last readings is under this (or under the band, if narrower)
MEAN_SIGMAS = 3.0  # ... with enough readings that the mean's noise is a third of that
MAX_READINGS = 32  # the most readings the mean takes (a noise so high needs more says so by staying out of rest)


def band_of(noise_rpm: float) -> float:
    """The band of rest for a speed reading with this noise (1 sigma)."""
    return max(STOPPED_RPM, BAND_SIGMAS * noise_rpm)


class RestWatch:
    """Feed it each speed reading with its time; at rest once the speed has stayed inside the band long enough and
    the mean of the last readings is near zero.

    band_rpm: one reading's band, BAND_SIGMAS noises wide (band_of): the noise it implies sets how many readings
    the mean needs."""

    def __init__(self, band_rpm: float, settle_s: float = SETTLE_S) -> None:
        self.band_rpm = band_rpm
        self.settle_s = settle_s
        self.mean_band_rpm = min(band_rpm, REST_MEAN_RPM)
        noise = band_rpm / BAND_SIGMAS
        self.readings_needed = min(MAX_READINGS, max(2, math.ceil((MEAN_SIGMAS * noise / self.mean_band_rpm) ** 2)))
        self._since: float | None = None
        self._last: deque[float] = deque(maxlen=self.readings_needed)

    def at_rest(self, now: float, speed_rpm: float) -> bool:
        """Whether the axis is at rest after this reading."""
        if abs(speed_rpm) >= self.band_rpm:
            self._since = None
            self._last.clear()
            return False
        if self._since is None:
            self._since = now
        self._last.append(speed_rpm)
        return (
            len(self._last) >= self.readings_needed
            and now - self._since >= self.settle_s
            and abs(self.mean_rpm) < self.mean_band_rpm
        )

    def __len__(self) -> int:
        """How many readings the mean takes now (the last ones inside the band)."""
        return len(self._last)

    @property
    def mean_rpm(self) -> float:
        """The mean of the last readings inside the band (nan before the first)."""
        return sum(self._last) / len(self._last) if self._last else math.nan
