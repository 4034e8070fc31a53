"""Live monitoring: poll monitor entries with coalesced reads at a target rate, keep statistics, log CSV."""

from __future__ import annotations

import csv
import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import IO, Literal

from servotool.clock import Clock, RealClock, utc_now
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.model.roles import readable_by_role

KEY_MONITOR_ROLES = (
    "speed_feedback",
    "speed_command",
    "torque_feedback",
    "position_feedback",
    "following_error",
    "load_rate",
    "current_rms",
    "bus_voltage",
)


def default_entries(profile: Profile) -> list[Entry]:
    """The profile's key monitors, by role."""
    found = readable_by_role(profile, KEY_MONITOR_ROLES)
    if not found:
        found = [e for e in profile.of_class("Un") if e.readable][:6]
    if not found:
        raise UsageError(f"profile {profile.id} has no readable monitor entries")
    return found


def check_rate(rate_hz: float) -> float:
    """A sampling rate must be a finite number of samples per second above zero."""
    if not (math.isfinite(rate_hz) and rate_hz > 0):
        raise UsageError(
            f"bad --rate {rate_hz:g}: must be a number of samples per second > 0 "
            "(a rate above what the link can do polls as fast as it can)"
        )
    return rate_hz


def check_duration(duration_s: float | None) -> float | None:
    """A duration, when given, must be a finite number of seconds above zero."""
    if duration_s is not None and not (math.isfinite(duration_s) and duration_s > 0):
        raise UsageError(f"bad --duration {duration_s:g}: must be a number of seconds > 0")
    return duration_s


def resolve_entries(profile: Profile, codes: list[str]) -> list[Entry]:
    """The entries to monitor (default: the key monitors); UsageError for unknown or unreadable codes."""
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

    def sparkline(self, width: int | None = None) -> str:
        """The trend as block characters, at most `width` of the latest values, scaled to their own range."""
        bars = "▁▂▃▄▅▆▇█"
        values = list(self.trend)[-width:] if width is not None else list(self.trend)
        if not values or width == 0:
            return ""
        lo, hi = min(values), max(values)
        span = hi - lo or 1.0
        return "".join(bars[min(7, int((v - lo) / span * 7.999))] for v in values)


@dataclass
class Sample:
    t: float  # seconds since the start of monitoring
    wall: datetime
    values: dict[str, float | int]


class Monitor:
    """Polls entries of one drive; each sample is one or a few coalesced requests."""

    def __init__(self, drive: Drive, entries: list[Entry], clock: Clock | None = None) -> None:
        self.drive = drive
        self.clock = clock or RealClock()
        self.entries = entries
        self.series = {e.code: Series(e) for e in entries}
        self.samples = 0
        self._t0: float | None = None
        self.elapsed = 0.0

    def sample(self) -> Sample:
        now, wall = self.clock.now(), utc_now(self.clock)
        if self._t0 is None:
            self._t0 = now
        readings = self.drive.read_entries(self.entries)
        values = {r.entry.code: raw_to_eng(r.entry, r.raw) for r in readings}
        for code, v in values.items():
            self.series[code].add(float(v))
        self.samples += 1
        self.elapsed = now - self._t0
        return Sample(self.elapsed, wall, values)

    @property
    def achieved_rate(self) -> float | None:
        """Samples per second over the intervals measured so far; None until there are two samples."""
        return (self.samples - 1) / self.elapsed if self.samples > 1 and self.elapsed > 0 else None

    def run(
        self,
        rate_hz: float,
        duration_s: float | None,
        samples: int | None = None,
        stop: Callable[[], bool] | None = None,
    ) -> Iterator[Sample]:
        """Yield samples at up to rate_hz (a rate the link cannot keep up with: as fast as it can) until
        duration/samples/stop."""
        period = 1.0 / check_rate(rate_hz)
        check_duration(duration_s)
        start = self.clock.now()
        n = 0
        while True:
            yield self.sample()
            n += 1
            if samples is not None and n >= samples:
                return
            if stop is not None and stop():
                return
            next_at = start + n * period
            now = self.clock.now()
            if duration_s is not None and (max(next_at, now) - start) >= duration_s:
                return
            if next_at > now:
                self.clock.sleep(next_at - now)


CsvMode = Literal["new", "replace", "append"]


class CsvLog:
    """Timestamped samples for a spreadsheet: timestamp, elapsed_s, then one column per entry ('CODE [unit]').

    Opened (and so checked) before the drive is: an existing file is refused in mode "new", replaced only once
    the first sample arrives in mode "replace", and extended in mode "append" only when its columns are the same.
    A file this log created but never wrote a sample to is removed again on close.
    """

    def __init__(self, path: Path, entries: list[Entry], mode: CsvMode = "new") -> None:
        self.path = path
        self._codes = [e.code for e in entries]
        self.header = ["timestamp", "elapsed_s", *[f"{e.code} [{e.unit}]" if e.unit else e.code for e in entries]]
        self.rows = 0
        existed = path.exists()
        if path.is_dir():
            raise UsageError(f"cannot write {path}: it is a directory")
        if mode == "append" and existed:
            self._check_columns()
        try:
            # "x" never replaces a file; "a" never truncates one before we have a sample to put in its place.
            self._fh: IO[str] = path.open("x" if mode == "new" else "a", newline="", encoding="utf-8", buffering=1)
        except FileExistsError:
            raise UsageError(f"{path} exists; pass --force to replace it or --append to add to it") from None
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None
        self._created = not existed
        self._truncate = mode == "replace" and existed
        self._header_due = not (mode == "append" and existed and path.stat().st_size > 0)
        self._writer = csv.writer(self._fh)

    def _check_columns(self) -> None:
        try:
            with self.path.open(newline="", encoding="utf-8") as fh:
                first = next(csv.reader(fh), None)
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise UsageError(f"cannot append to {self.path}: {getattr(exc, 'strerror', None) or exc}") from None
        if first is not None and first != self.header:
            raise UsageError(
                f"cannot append to {self.path}: its columns ({', '.join(first[2:]) or 'none'}) "
                f"differ from these ({', '.join(self.header[2:])})"
            )

    def write(self, sample: Sample) -> None:
        if self._truncate:
            self._fh.truncate(0)
            self._truncate = False
        if self._header_due:
            self._writer.writerow(self.header)
            self._header_due = False
        self._writer.writerow(
            [
                sample.wall.isoformat(timespec="milliseconds"),
                f"{sample.t:.4f}",
                *[sample.values[c] for c in self._codes],
            ]
        )
        self.rows += 1

    def close(self) -> None:
        self._fh.close()
        if self._created and self.rows == 0:
            self.path.unlink(missing_ok=True)
