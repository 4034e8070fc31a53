"""Live monitoring: poll monitor entries with coalesced reads at a target rate, keep statistics, log CSV."""

from __future__ import annotations

import csv
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import IO

from servotool.codec import raw_to_eng
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.profile import Entry, Profile

KEY_MONITOR_ROLES = ("speed_feedback", "speed_command", "torque_feedback", "position_feedback", "following_error",
                     "load_rate", "current_rms", "bus_voltage")


def default_entries(profile: Profile) -> list[Entry]:
    """The profile's key monitors, by role."""
    found: list[Entry] = []
    for role in KEY_MONITOR_ROLES:
        e = profile.role(role)
        if e is not None and e.readable and e not in found:
            found.append(e)
    if not found:
        found = [e for e in profile.of_class("Un") if e.readable][:6]
    if not found:
        raise UsageError(f"profile {profile.id} has no readable monitor entries")
    return found


def resolve_entries(profile: Profile, codes: list[str]) -> list[Entry]:
    if not codes:
        return default_entries(profile)
    entries = [profile.entry(c) for c in codes]
    for e in entries:
        if not e.readable:
            raise UsageError(f"{e.code} ({e.name}) cannot be read")
    return entries


@dataclass
class Series:
    """Running statistics and a short trend of one monitored entry."""

    entry: Entry
    last: float = 0.0
    low: float = float("inf")
    high: float = float("-inf")
    trend: deque[float] = field(default_factory=lambda: deque(maxlen=40))

    def add(self, value: float) -> None:
        self.last = value
        self.low = min(self.low, value)
        self.high = max(self.high, value)
        self.trend.append(value)

    def sparkline(self) -> str:
        bars = "▁▂▃▄▅▆▇█"
        if not self.trend:
            return ""
        lo, hi = min(self.trend), max(self.trend)
        span = hi - lo or 1.0
        return "".join(bars[min(7, int((v - lo) / span * 7.999))] for v in self.trend)


@dataclass
class Sample:
    t: float           # seconds since the start of monitoring
    wall: datetime
    values: dict[str, float | int]


class Monitor:
    """Polls entries of one drive; each sample is one or a few coalesced requests."""

    def __init__(self, drive: Drive, entries: list[Entry]) -> None:
        self.drive = drive
        self.entries = entries
        self.series = {e.code: Series(e) for e in entries}
        self.samples = 0
        self._t0: float | None = None
        self.elapsed = 0.0

    def sample(self) -> Sample:
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        readings = self.drive.read_entries(self.entries)
        values = {r.entry.code: raw_to_eng(r.entry, r.raw) for r in readings}
        for code, v in values.items():
            self.series[code].add(float(v))
        self.samples += 1
        self.elapsed = now - self._t0
        return Sample(self.elapsed, datetime.now(UTC), values)

    @property
    def achieved_rate(self) -> float:
        return (self.samples - 1) / self.elapsed if self.samples > 1 and self.elapsed > 0 else 0.0

    def run(self, rate_hz: float, duration_s: float | None, samples: int | None = None,
            stop: Callable[[], bool] | None = None) -> Iterator[Sample]:
        """Yield samples at up to rate_hz (0 = as fast as the link allows) until duration/samples/stop."""
        if rate_hz < 0:
            raise UsageError("--rate must be >= 0")
        period = 1.0 / rate_hz if rate_hz > 0 else 0.0
        start = time.monotonic()
        n = 0
        while True:
            yield self.sample()
            n += 1
            if samples is not None and n >= samples:
                return
            if stop is not None and stop():
                return
            next_at = start + n * period
            now = time.monotonic()
            if duration_s is not None and (max(next_at, now) - start) >= duration_s:
                return
            if next_at > now:
                time.sleep(next_at - now)


class CsvLog:
    """Timestamped samples for a spreadsheet: timestamp, elapsed_s, then one column per entry ('CODE [unit]')."""

    def __init__(self, path: Path, entries: list[Entry]) -> None:
        self.path = path
        try:
            self._fh: IO[str] = path.open("w", newline="", encoding="utf-8")
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror}") from None
        self._writer = csv.writer(self._fh)
        self._codes = [e.code for e in entries]
        self._writer.writerow(["timestamp", "elapsed_s", *[f"{e.code} [{e.unit}]" if e.unit else e.code
                                                              for e in entries]])

    def write(self, sample: Sample) -> None:
        self._writer.writerow([sample.wall.isoformat(timespec="milliseconds"), f"{sample.t:.4f}",
                               *[sample.values[c] for c in self._codes]])

    def close(self) -> None:
        self._fh.close()
