"""The guard that keeps an identification's moves inside their travel band (tuning.identify): a move stops early
where its stopping distance would carry the axis out of the band, as far as the pilot and the moves so far showed
the axis to run on. Drift (gravity, overshoot) must not add up to the travel limit.

A JOG's soft limit (motion.travel.TravelGuard) is its twin for a motion of unknown length: it reads the position
and stops at a fixed distance from the limit. Here the moves are planned, the band sits inside the limit that the
sampler enforces, and the guard learns from the pilot and each move how far the axis runs on."""

from __future__ import annotations

import math
from dataclasses import dataclass

OWN_MARGIN = 2.0  # an own segment's end is predicted this many times its longest lag yet beyond it


@dataclass
class BandGuard:
    """What the guard has learnt of the axis; band [lo, hi] in rev, set after the pilot (None: no guard yet)."""

    band: tuple[float, float] | None = None
    # How far the axis really goes per nominal revolution (the pilot's excursion: a stop command's latency in it).
    stretch: float = 1.0
    # The loop's lag (s): how much further than its ramp the axis coasted after a stop command, per speed. A speed
    # loop configured for a fraction of the real inertia lags its ramps by tens of ms, more with high friction (the
    # integral winds up at breakaway).
    lag_s: float = 0.0
    # The longest time between two samples seen so far (rest check, moves): the guard must foresee a check that
    # comes that late. A host stalls (a loaded laptop, a scheduler's 16 ms tick, a USB adapter's latency timer) and
    # an axis at 900 rpm covers 0.2 rev in 13 ms: more than the band leaves.
    gap_s: float = 0.0
    # How long (s, at speed) the moves that their own segment ended ran past it, the longest yet (None: none yet).
    own_lag_s: float | None = None
    # The running move: where it started (rev), its direction, speed (rpm) and own segment (rev, None: the host stops
    # it) with the speed it peaks at (rpm: a segment shorter than its ramps turns back before the speed), where that
    # segment will stop it, and the furthest it went.
    origin: float = 0.0
    direction: int = 0
    speed: float = 0.0
    own_rev: float | None = None
    own_peak: float = 0.0
    own_end: float | None = None
    reach: float = 0.0

    def begin(
        self, pred: float, direction: int, speed: float, own_rev: float | None, full_rev: float | None = None
    ) -> None:
        """A move starts from pred (rev) in direction to `speed`; own_rev: its own segment, which the drive brakes
        by itself at its end (full_rev: the segment's length had it reached the speed, None: as long). It stops as
        far past it as the own segments so far ran at its peak speed, twice over, else stretched as the pilot's
        stopped move."""
        self.origin, self.direction, self.speed, self.own_rev, self.reach = pred, direction, speed, own_rev, 0.0
        if own_rev is None:
            self.own_end = None
            return
        reach, self.own_peak = self._own_reach(own_rev, full_rev or own_rev, speed)
        self.own_end = pred + direction * reach

    def _own_reach(self, own_rev: float, full_rev: float, speed: float) -> tuple[float, float]:
        """How far from its start an own segment of own_rev (full_rev had it reached `speed`) is predicted to stop,
        and the speed it peaks at (up and down the same ramps, a shorter one turns back at the root of its share)."""
        peak = speed * math.sqrt(min(1.0, own_rev / full_rev)) if full_rev > 0 else speed
        if self.own_lag_s is None:
            return own_rev * self.stretch, peak
        return own_rev + OWN_MARGIN * self.own_lag_s * peak / 60.0, peak

    def own_room(self, pred: float, direction: int, speed: float, full_rev: float) -> float | None:
        """The longest own segment (at most full_rev, its length at `speed`) that a move from pred in direction may
        have for its stop, as begin predicts it, to stay inside the band (the drive then brakes it there by itself,
        however late the host looks again: a stall cannot carry it out); None before the band is set."""
        if self.band is None:
            return None
        edge = self.band[1] if direction > 0 else self.band[0]
        room = direction * (edge - pred)
        if room <= 0 or full_rev <= 0:
            return 0.0
        if self._own_reach(full_rev, full_rev, speed)[0] <= room:
            return full_rev
        if self.own_lag_s is None:
            return room / self.stretch
        # own + k sqrt(own) = room (k: the run-past at the peak speed of a segment of sqrt(own / full_rev))
        k = OWN_MARGIN * self.own_lag_s * speed / 60.0 / math.sqrt(full_rev)
        root = (-k + math.sqrt(k * k + 4.0 * room)) / 2.0
        return min(full_rev, root * root)

    def must_stop(self, pred: float, v: float, ramp_s: float, interval_s: float) -> bool:
        """Whether stopping the running move now still keeps the axis (at pred rev, v rpm, its ramp ramp_s, sampled
        every interval_s) inside the band: the ramp's stopping distance, stretched as the pilot showed, plus the
        travel until a stop command can act and the loop's lag. A move whose own segment stops it inside the band
        the drive brakes there by itself, with no command to wait for."""
        own_end = self.own_end
        if self.band is None or (own_end is not None and self.band[0] <= own_end <= self.band[1]):
            return False
        direction, speed = self.direction, self.speed
        lo, hi = self.band
        # Until a stop command acts: the next sample (as late as the longest gap yet: beyond the usual interval the
        # ramp goes on accelerating) and the write, then the loop's lag.
        late = max(0.0, self.gap_s - interval_s)
        v_late = min(speed, v + speed / ramp_s * late)
        stop_rev = v / 60.0 * (2.0 * interval_s + self.lag_s) + (v + v_late) / 2.0 / 60.0 * late
        stop_rev += self.stretch * v_late * v_late * ramp_s / (2 * speed) / 60.0
        return pred + stop_rev > hi if direction > 0 else pred - stop_rev < lo

    def rest_at(self, pred: float, v: float, ramp_s: float, interval_s: float) -> float:
        """Where the running move would come to rest if stopped at the next sample (pred rev, v rpm now): its ramp's
        stopping distance, stretched as the pilot showed, plus the travel until a stop command acts and the loop's
        lag."""
        stop_rev = v / 60.0 * (interval_s + self.lag_s) + self.stretch * v * v * ramp_s / (2 * self.speed) / 60.0
        return pred + self.direction * stop_rev

    def saw(self, pred: float) -> None:
        """The axis is at pred (the sampler's position, each sample)."""
        self.reach = max(self.reach, self.direction * (pred - self.origin))

    def ended(self) -> None:
        """The running move has ended at rest: where its own segment carried it, how far it ran past it."""
        if self.own_rev is not None and self.own_peak > 0:
            self.own_lag_s = max(self.own_lag_s or 0.0, (self.reach - self.own_rev) / (self.own_peak / 60.0))

    def coasted(self, coast_rev: float, v_stop: float) -> None:
        """After a stop command at v_stop rpm the axis went coast_rev further than its ramp."""
        self.lag_s = max(self.lag_s, coast_rev / (v_stop / 60.0))
