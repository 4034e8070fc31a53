"""The identification's sampling: speed and torque in as few requests as the profile allows, position when it is
due, and the travel band the axis has covered."""

from __future__ import annotations

import csv
import math
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from servotool.clock import Clock
from servotool.drive import Drive, coalesce_reads
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.tuning.preflight import FEATURE

# Position costs a request of its own on every profile (no profile maps it next to speed and torque with readable
# registers between): it is read at most this share of the link's time, and at least every POSITION_MAX_GAP_S.
# Between reads the travel is predicted from the speed: on a slow line a fixed fast pace of position reads would
# take the samples the estimator needs.
POSITION_SHARE = 0.06
POSITION_MIN_GAP_S = 0.05
POSITION_MAX_GAP_S = 0.5
# A drive takes its reading when the request arrives: a sample is stamped when its request goes out, and one whose
# exchange took longer than the line's shortest recent one by more than this (s, or this share of that exchange) is
# kept for the motion's guard but left out of the fit: the host was late somewhere inside it (descheduled before the
# request went out, or after the answer came), so when the drive took the reading is not known.
LATE_S = 0.001
LATE_SHARE = 0.25
LATE_HISTORY = 32
GAP_READ_EXCHANGES = 4.0  # a gap in the fitted samples longer than this many exchanges has the position read after it


@dataclass
class Trace:
    """What an identification sampled: times (s from its start), speed (rpm), torque (% of rated), position (rev)."""

    t: list[float] = field(default_factory=list)
    speed: list[float] = field(default_factory=list)
    torque: list[float] = field(default_factory=list)
    position: list[float | None] = field(default_factory=list)  # None where position was not read
    # When speed and torque cannot share one request (SD25 reads at most 10 registers), the speed is read a
    # request earlier: its own times, to bring it onto the torque's time base before the fit.
    speed_t: list[float] = field(default_factory=list)
    # False where the sample's exchange overran the line's own time (LATE_S): its time is not known, no fit uses it.
    on_time: list[bool] = field(default_factory=list)
    # (from, to), s from the start: where the sampling paused by the identification's own choice (a fit between moves,
    # the drive holding). The gap it leaves is no host stall, though a ringing load may still move in it.
    paused: list[tuple[float, float]] = field(default_factory=list)

    def fitted(self) -> tuple[list[float], list[float], list[float], list[float]]:
        """(times, speed at those times, torque, position or NaN where none was read) of the samples whose time is
        known: what the fit may use."""
        speed = self.aligned_speed()
        keep = self.on_time if len(self.on_time) == len(self.t) else [True] * len(self.t)
        chosen = [i for i, ok in enumerate(keep) if ok]
        position = [math.nan if (x := self.position[i]) is None else x for i in chosen]
        return [self.t[i] for i in chosen], [speed[i] for i in chosen], [self.torque[i] for i in chosen], position

    @property
    def late(self) -> int:
        """Samples left out of the fit because their exchange overran the line's time."""
        return self.on_time.count(False)

    @property
    def speed_between_reads(self) -> bool:
        """Whether the speed was read apart from the torque, so that aligned_speed interpolates it."""
        return len(self.speed_t) == len(self.t) >= 2

    def aligned_speed(self) -> list[float]:
        """Speed at the torque's sample times; the speed itself if read together.

        Cubic (Hermite, slopes from the neighbours) between speed reads, held after the last: a straight line
        between reads half an interval away misplaces a curving speed (a sluggish loop rings through its ramps) and
        biases J."""
        if not self.speed_between_reads:
            return list(self.speed)
        ts, v, t = np.asarray(self.speed_t), np.asarray(self.speed), np.asarray(self.t)
        slope = np.gradient(v, ts)
        i = np.clip(np.searchsorted(ts, t) - 1, 0, ts.size - 2)
        h = ts[i + 1] - ts[i]
        x = np.clip((t - ts[i]) / h, 0.0, 1.0)
        out = (
            (2 * x**3 - 3 * x**2 + 1) * v[i]
            + (x**3 - 2 * x**2 + x) * h * slope[i]
            + (3 * x**2 - 2 * x**3) * v[i + 1]
            + (x**3 - x**2) * h * slope[i + 1]
        )
        return [float(s) for s in out]

    def rate(self) -> float:
        """Samples per second, first to last."""
        t = self.t
        return (len(t) - 1) / (t[-1] - t[0]) if len(t) > 1 and t[-1] > t[0] else 0.0

    def save(self, path: Path) -> None:
        try:
            with path.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["t_s", "speed_rpm", "torque_pct", "position_rev"])
                for t, v, q, x in zip(self.t, self.speed, self.torque, self.position, strict=True):
                    w.writerow([f"{t:.5f}", f"{v:.2f}", f"{q:.2f}", "" if x is None else f"{x:.4f}"])
        except OSError as exc:
            raise UsageError(f"cannot write {path}: {exc.strerror}") from None


class TravelLimitReached(Exception):
    """Raised by Sampler.sample when the band covered exceeds the limit (the caller words it)."""


class Sampler:
    """One drive's identification samples and the travel band they show."""

    def __init__(
        self, drive: Drive, timing: Clock, travel_limit_rev: float, beat: Callable[[], None] | None = None
    ) -> None:
        p = drive.profile
        self.drive, self.timing, self.limit, self.beat = drive, timing, travel_limit_rev, beat
        self.speed_e, self.torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
        self.pos_e = p.role("position_feedback")
        self.together = len(coalesce_reads(p, [self.speed_e, self.torque_e])) == 1  # one request carries both
        # Position free with speed and torque (same number of requests): read it with every sample.
        self.pos_free = self.pos_e is not None and len(
            coalesce_reads(p, [self.speed_e, self.torque_e, self.pos_e])
        ) == len(coalesce_reads(p, [self.speed_e, self.torque_e]))
        self.counts = p.motor.counts_per_rev if p.motor is not None else 1
        self.trace = Trace()
        self.t0 = timing.now()
        self.pos: float | None = None
        self.pos_t = self.t0
        self.pos_every = POSITION_MIN_GAP_S
        self.lo = self.hi = self.pred = 0.0
        self._took: deque[float] = deque(maxlen=LATE_HISTORY)
        self._fitted_at = math.inf  # when the last sample the fit may use was taken

    @property
    def travel_rev(self) -> float:
        return self.hi - self.lo

    def elapsed(self) -> float:
        return self.timing.now() - self.t0

    @contextmanager
    def paused(self) -> Iterator[None]:
        """No samples inside, by the caller's own choice (a fit while the drive holds): the time is kept in
        Trace.paused, so that the gap it leaves is not named a host stall."""
        began = self.elapsed()
        try:
            yield
        finally:
            self.trace.paused.append((began, self.elapsed()))

    def rate(self) -> float:
        """Samples per second so far, first to last (the motion's own set-up and put-back writes left out)."""
        return self.trace.rate()

    def interval(self) -> float:
        """The last sampling interval (0 before the second sample)."""
        t = self.trace.t
        return t[-1] - t[-2] if len(t) > 1 else 0.0

    def _read(self) -> tuple[float, float, int | None, float]:
        """(speed, torque, position raw or None, when the torque's request went out); the speed's own time is kept
        where it takes a request of its own."""
        d, trace = self.drive, self.trace
        pos_raw = None
        if self.together:
            sent = self.timing.now()
            entries = [self.speed_e, self.torque_e] + ([self.pos_e] if self.pos_free and self.pos_e else [])
            readings = d.read_entries(entries)
            if len(readings) > 2:
                pos_raw = readings[2].raw
        else:
            trace.speed_t.append(self.timing.now() - self.t0)
            readings = d.read_entries([self.speed_e])
            sent = self.timing.now()
            readings += d.read_entries([self.torque_e])
        return (
            float(raw_to_eng(self.speed_e, readings[0].raw)),
            float(raw_to_eng(self.torque_e, readings[1].raw)),
            pos_raw,
            sent,
        )

    def _on_time(self, took: float) -> bool:
        """Whether an exchange that took `took` s kept to the line's time (the shortest of the recent ones)."""
        self._took.append(took)
        usual = min(self._took)
        return took <= usual + max(LATE_S, LATE_SHARE * usual)

    def sample(self) -> None:
        """One sample of speed and torque (and position when due); raises TravelLimitReached past the limit."""
        trace = self.trace
        start = self.timing.now()
        speed, torque, pos_raw, sent = self._read()
        now = self.timing.now()
        if trace.t:  # travel between position reads, from the speed (checked before it is reached)
            self.pred += 0.5 * (speed + trace.speed[-1]) / 60.0 * (sent - self.t0 - trace.t[-1])
        trace.t.append(sent - self.t0)
        trace.speed.append(speed)
        trace.torque.append(torque)
        trace.position.append(None)
        on_time = self._on_time(now - start)
        trace.on_time.append(on_time)
        # The fit's position is the speed's integral, which no gap in the fitted samples can be integrated across:
        # after one, the drive's position is read at once.
        after_gap = on_time and sent - self._fitted_at > GAP_READ_EXCHANGES * min(self._took)
        if on_time:
            self._fitted_at = sent
        if pos_raw is not None:
            self._position(pos_raw / self.counts, sent)
        elif self.pos_e is not None and (self.pos is None or now - self.pos_t >= self.pos_every or after_gap):
            asked = self.timing.now()
            x = self.drive.read_entries([self.pos_e])[0].raw / self.counts
            read_at = self.timing.now()
            self.pos_every = min(POSITION_MAX_GAP_S, max(POSITION_MIN_GAP_S, (read_at - asked) / POSITION_SHARE))
            self._position(x, read_at, speed / 60.0 * (asked - sent))
        # Travel from the position reads, predicted from the speed between them (from the speed alone where the
        # profile has no usable position feedback).
        self.lo, self.hi = min(self.lo, self.pred), max(self.hi, self.pred)
        if self.hi - self.lo > self.limit:
            raise TravelLimitReached
        if self.beat is not None:
            self.beat()

    def _position(self, x: float, now: float, since_sample: float = 0.0) -> None:
        """The drive's position `x` (rev), known at `now`; the sample's own is x less the `since_sample` rev the axis
        went on between the sample and the position's request (the drive takes both when a request arrives)."""
        self.trace.position[-1] = x - since_sample
        self.pos, self.pos_t, self.pred = x, now, x
        first = len(self.trace.t) == 1
        self.lo, self.hi = (x, x) if first else (min(self.lo, x), max(self.hi, x))
