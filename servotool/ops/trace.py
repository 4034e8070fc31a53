"""Triggered trace capture: entries sampled back to back (one coalesced read per sample), a trigger on any of them,
a pre-trigger ring buffer, single-shot or repeated captures, and the achieved rate and jitter.

The trigger logic (`Trigger`, `Window`, `TriggerBuffer`) sees only samples, so it is tested on synthetic data; the
`Tracer` adds the drive and the clock.
"""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from servotool.clock import Clock, RealClock
from servotool.drive import Drive, coalesce_reads
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.model.roles import readable_by_role
from servotool.words import count

TRIGGER_FORMS = (
    "CODE>LEVEL (rises through LEVEL), CODE<LEVEL (falls through LEVEL), CODE.BIT (a bit of a "
    "status word sets; BIT a number or the bit's name) or CODE.BIT=0 (it clears)"
)
TriggerKind = Literal["rising", "falling", "bit_set", "bit_clear"]
_LEVEL = re.compile(r"^\s*([^<>.=\s]+)\s*([<>])\s*(\S+)\s*$")
_BIT = re.compile(r"^\s*([^<>.=\s]+)\.(\w+)\s*(?:=\s*([01]))?\s*$")


@dataclass(frozen=True)
class Trigger:
    """When a capture starts: an entry's value (engineering units) crossing a level, or a bit changing."""

    entry: Entry
    kind: TriggerKind
    level: float = 0.0
    bit: int = 0
    text: str = ""

    def fires(self, prev: float | None, cur: float) -> bool:
        """Whether the step from the previous sample to this one is the trigger's edge (never on the first)."""
        if prev is None:
            return False
        if self.kind == "rising":
            return prev < self.level <= cur
        if self.kind == "falling":
            return prev > self.level >= cur
        was, now = int(prev) >> self.bit & 1, int(cur) >> self.bit & 1
        return (not was and bool(now)) if self.kind == "bit_set" else (bool(was) and not now)

    def describe(self) -> str:
        e = self.entry
        if self.kind in ("rising", "falling"):
            unit = f" {e.unit}" if e.unit else ""
            return f"{e.code} {'rises' if self.kind == 'rising' else 'falls'} through {self.level:g}{unit}"
        name = e.bits.get(self.bit)
        return f"{e.code} bit {self.bit}{f' ({name})' if name else ''} {'sets' if self.kind == 'bit_set' else 'clears'}"


def parse_trigger(profile: Profile, expr: str) -> Trigger:
    """A --trigger expression (see TRIGGER_FORMS) on one of the profile's readable entries."""
    if m := _LEVEL.match(expr):
        entry = _readable(profile, m.group(1))
        try:
            level = float(m.group(3))
        except ValueError:
            level = math.nan
        if not math.isfinite(level):
            raise UsageError(f"bad --trigger {expr!r}: {m.group(3)!r} is not a level in {entry.unit or 'its units'}")
        return Trigger(entry, "rising" if m.group(2) == ">" else "falling", level=level, text=expr.strip())
    if m := _BIT.match(expr):
        entry = _readable(profile, m.group(1))
        bit = _bit_number(entry, m.group(2), expr)
        return Trigger(entry, "bit_clear" if m.group(3) == "0" else "bit_set", bit=bit, text=expr.strip())
    raise UsageError(f"bad --trigger {expr!r}: use {TRIGGER_FORMS}")


def _readable(profile: Profile, code: str) -> Entry:
    entry = profile.entry(code)
    if not entry.readable:
        raise UsageError(f"{entry.code} ({entry.name}) cannot be read")
    return entry


def _bit_number(entry: Entry, name: str, expr: str) -> int:
    by_name = {v: k for k, v in entry.bits.items()}
    bit = int(name) if name.isdigit() else by_name.get(name)
    if bit is None:
        known = ", ".join(f"{k} {v}" for k, v in sorted(entry.bits.items())) or "none named"
        raise UsageError(f"bad --trigger {expr!r}: {entry.code} has no bit {name!r} (bits: {known})")
    if not 0 <= bit < 16 * entry.words:
        raise UsageError(f"bad --trigger {expr!r}: {entry.code} has bits 0..{16 * entry.words - 1}")
    return bit


MOTION_ROLES = ("speed_feedback", "speed_command", "torque_feedback", "position_feedback", "following_error")


def motion_entries(profile: Profile) -> list[Entry]:
    """What a motion's own trace records: the profile's speed, torque and position monitors, by role."""
    found = readable_by_role(profile, MOTION_ROLES)
    if not found:
        raise UsageError(f"profile {profile.id} maps no speed, torque or position monitor to trace")
    return found


@dataclass(frozen=True)
class Window:
    """How much a capture holds: a sample count or a duration, pre_share of it from before the trigger."""

    samples: int | None = None
    duration_s: float | None = None
    pre_share: float = 0.2

    def __post_init__(self) -> None:
        if (self.samples is None) == (self.duration_s is None):
            raise UsageError("give a capture size: --samples N or --duration SECONDS, not both")
        if self.samples is not None and self.samples < 2:
            raise UsageError(f"bad --samples {self.samples}: a capture needs at least 2 samples")
        if self.duration_s is not None and not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise UsageError(f"bad --duration {self.duration_s:g}: must be a number of seconds > 0")
        if not (math.isfinite(self.pre_share) and 0 <= self.pre_share < 1):
            raise UsageError(f"bad --pre {self.pre_share * 100:g} %: the pre-trigger share is 0..99 %")

    @property
    def pre_samples(self) -> int | None:
        return None if self.samples is None else min(self.samples - 1, round(self.samples * self.pre_share))


@dataclass(frozen=True)
class TraceSample:
    t: float  # seconds since sampling started (the middle of the sample's reads)
    values: dict[str, float]


@dataclass
class Capture:
    """One capture: times relative to the trigger (the trigger sample at 0), one column per entry code."""

    index: int
    trigger_t: float  # seconds since sampling started
    t: list[float]
    values: dict[str, list[float]]
    pre_samples: int

    @classmethod
    def of(cls, index: int, samples: list[TraceSample], trigger_at: int, codes: list[str]) -> Capture:
        t0 = samples[trigger_at].t if samples else 0.0
        return cls(
            index, t0, [s.t - t0 for s in samples], {c: [s.values[c] for s in samples] for c in codes}, trigger_at
        )

    @property
    def timing(self) -> Timing:
        return Timing.of(self.t)


@dataclass(frozen=True)
class Timing:
    """Sampling achieved: mean rate and the spread of the sample intervals."""

    samples: int
    rate_hz: float | None
    jitter_ms: float | None  # standard deviation of the intervals
    max_gap_ms: float | None

    @classmethod
    def of(cls, t: list[float]) -> Timing:
        if len(t) < 2:
            return cls(len(t), None, None, None)
        dt = np.diff(np.asarray(t, dtype=float))
        mean = float(dt.mean())
        return cls(len(t), 1.0 / mean if mean > 0 else None, float(dt.std()) * 1e3, float(dt.max()) * 1e3)

    def describe(self) -> str:
        if self.rate_hz is None:
            return count(self.samples, "sample")
        return (
            f"{self.samples} samples, {self.rate_hz:.1f} samples/s, jitter {self.jitter_ms:.2f} ms "
            f"(longest interval {self.max_gap_ms:.1f} ms)"
        )


class TriggerBuffer:
    """Samples in, captures out: a ring buffer keeps the pre-trigger share until the trigger fires, then the rest of
    the window is collected. After a capture it re-arms; the next capture needs a new edge."""

    def __init__(self, trigger: Trigger | None, window: Window, codes: list[str]) -> None:
        self.trigger, self.window, self.codes = trigger, window, codes
        pre = window.pre_samples if trigger is not None else 0
        self._ring: deque[TraceSample] = deque(maxlen=pre) if pre is not None else deque()
        self._pre_s = window.pre_share * window.duration_s if window.duration_s is not None and trigger else 0.0
        self._prev: float | None = None
        self._taken: list[TraceSample] | None = None  # the capture being filled, from its first sample
        self._trigger_at = 0
        self.captures = 0
        self.low, self.high = math.inf, -math.inf  # the trigger entry's range seen while armed

    @property
    def armed(self) -> bool:
        """Waiting for the trigger (not filling a capture)."""
        return self._taken is None

    def feed(self, s: TraceSample) -> Capture | None:
        value = s.values[self.trigger.entry.code] if self.trigger is not None else 0.0
        if self._taken is None:
            self.low, self.high = min(self.low, value), max(self.high, value)
            if self.trigger is None or self.trigger.fires(self._prev, value):
                self._trim(s.t)
                self._taken = [*self._ring, s]
                self._trigger_at = len(self._ring)
                self._ring.clear()
            else:
                self._ring.append(s)
                self._trim(s.t)
                if self.window.duration_s is not None and not self._pre_s:
                    self._ring.clear()
        else:
            self._taken.append(s)
        self._prev = value
        return self._finish() if self._full() else None

    def _trim(self, now: float) -> None:
        """A duration window's ring holds its pre-trigger time, no more."""
        while self._pre_s and self._ring and self._ring[0].t < now - self._pre_s - 1e-9:
            self._ring.popleft()

    def _full(self) -> bool:
        taken = self._taken
        if taken is None:
            return False
        w = self.window
        if w.samples is not None:
            return len(taken) >= w.samples
        assert w.duration_s is not None
        post = w.duration_s - (self._pre_s if self.trigger is not None else 0.0)
        return taken[-1].t - taken[self._trigger_at].t >= post - 1e-9

    def _finish(self) -> Capture:
        assert self._taken is not None
        self.captures += 1
        cap = Capture.of(self.captures, self._taken, self._trigger_at, self.codes)
        self._taken = None
        self.low, self.high = math.inf, -math.inf
        return cap


class Sampler:
    """Reads a set of entries in as few requests as the profile allows, timestamping each sample by the one clock."""

    def __init__(self, drive: Drive, entries: list[Entry], clock: Clock | None = None) -> None:
        self.drive, self.entries = drive, entries
        self.clock = clock or RealClock()
        self.requests_per_sample = len(coalesce_reads(drive.profile, entries))
        self.t0 = self.clock.now()
        self.samples: list[TraceSample] = []
        self.keep = False  # keep every sample (a recording), not only the last

    def sample(self) -> TraceSample:
        before = self.clock.now()
        readings = self.drive.read_entries(self.entries)
        after = self.clock.now()
        s = TraceSample(
            (before + after) / 2 - self.t0, {r.entry.code: float(raw_to_eng(r.entry, r.raw)) for r in readings}
        )
        if self.keep:
            self.samples.append(s)
        return s

    def sample_for(self, seconds: float) -> None:
        """Sample back to back for this long (at least once): the idle time of a motion loop, put to use."""
        self.keep = True
        end = self.clock.now() + seconds
        self.sample()
        while self.clock.now() < end:
            self.sample()

    def recording(self) -> Capture:
        """Every sample kept so far as one capture from the start (no trigger)."""
        codes = [e.code for e in self.entries]
        return Capture(1, 0.0, [s.t for s in self.samples], {c: [s.values[c] for s in self.samples] for c in codes}, 0)


@dataclass
class Tracer:
    """Triggered captures from one drive: `run()` yields each capture as it completes."""

    drive: Drive
    entries: list[Entry]
    trigger: Trigger | None
    window: Window
    repeat: int = 1  # captures to take; 0: until stopped
    timeout_s: float | None = None  # give up when the trigger has not fired this long after arming
    clock: Clock = field(default_factory=RealClock)
    stop: Callable[[], bool] | None = None
    timed_out: bool = False
    samples: int = 0

    def __post_init__(self) -> None:
        codes = [e.code for e in self.entries]
        if self.trigger is not None and self.trigger.entry.code not in codes:
            self.entries = [*self.entries, self.trigger.entry]
        self.sampler = Sampler(self.drive, self.entries, self.clock)
        self.buffer = TriggerBuffer(self.trigger, self.window, [e.code for e in self.entries])

    def run(self) -> Iterator[Capture]:
        taken, armed_at = 0, 0.0
        while self.repeat == 0 or taken < self.repeat:
            s = self.sampler.sample()
            self.samples += 1
            cap = self.buffer.feed(s)
            if cap is not None:
                taken += 1
                armed_at = s.t
                yield cap
            elif self.buffer.armed and self.timeout_s is not None and s.t - armed_at > self.timeout_s:
                self.timed_out = True
                return
            if self.stop is not None and self.stop():
                return
