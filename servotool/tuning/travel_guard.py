"""The guard that keeps an identification's moves inside their travel band (tuning.identify): a move stops early
where its stopping distance would carry the axis out of the band, as far as the pilot and the moves so far showed
the axis to run on. Drift (gravity, overshoot) must not add up to the travel limit."""

from __future__ import annotations

from dataclasses import dataclass

OWN_MARGIN = 2.0      # an own segment's end is predicted this many times its longest lag yet beyond it


@dataclass
class TravelGuard:
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
    # The running move: where it started (rev), its direction and the furthest it went that way.
    origin: float = 0.0
    direction: int = 0
    reach: float = 0.0

    def must_stop(self, pred: float, v: float, direction: int, speed: float, ramp_s: float, interval_s: float,
                  own_end: float | None = None) -> bool:
        """Whether stopping now still keeps the axis (at pred rev, v rpm, in a move to `speed` in ramp_s, sampled
        every interval_s) inside the band: the ramp's stopping distance, stretched as the pilot showed, plus the
        travel until a stop command can act and the loop's lag. own_end: where the move's own segment stops it;
        inside the band the drive brakes it there by itself, with no command to wait for."""
        if self.band is None or (own_end is not None and self.band[0] <= own_end <= self.band[1]):
            return False
        lo, hi = self.band
        # Until a stop command acts: the next sample (as late as the longest gap yet: beyond the usual interval the
        # ramp goes on accelerating) and the write, then the loop's lag.
        late = max(0.0, self.gap_s - interval_s)
        v_late = min(speed, v + speed / ramp_s * late)
        stop_rev = v / 60.0 * (2.0 * interval_s + self.lag_s) + (v + v_late) / 2.0 / 60.0 * late
        stop_rev += self.stretch * v_late * v_late * ramp_s / (2 * speed) / 60.0
        return pred + stop_rev > hi if direction > 0 else pred - stop_rev < lo

    def own_end(self, pred: float, direction: int, own_rev: float | None, speed: float) -> float | None:
        """Where a move from pred that its own segment of own_rev carries will stop (None: the host stops it): as
        far past it as the own segments so far ran, twice over, else stretched as the pilot's stopped move."""
        if own_rev is None:
            return None
        if self.own_lag_s is None:
            return pred + direction * own_rev * self.stretch
        return pred + direction * (own_rev + OWN_MARGIN * self.own_lag_s * speed / 60.0)

    def begin(self, pred: float, direction: int) -> None:
        """A move starts from pred (rev) in direction."""
        self.origin, self.direction, self.reach = pred, direction, 0.0

    def saw(self, pred: float) -> None:
        """The axis is at pred (the sampler's position, each sample)."""
        self.reach = max(self.reach, self.direction * (pred - self.origin))

    def ran_own(self, own_rev: float, speed: float) -> None:
        """The running move, which its own segment of own_rev carried at `speed`, has ended: how far past it."""
        self.own_lag_s = max(self.own_lag_s or 0.0, (self.reach - own_rev) / (speed / 60.0))

    def coasted(self, coast_rev: float, v_stop: float) -> None:
        """After a stop command at v_stop rpm the axis went coast_rev further than its ramp."""
        self.lag_s = max(self.lag_s, coast_rev / (v_stop / 60.0))
