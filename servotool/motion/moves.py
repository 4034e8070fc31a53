"""Motions made of short moves from rest (identification): each move's settings in the fewest requests, a segment
route's move stopped by a segment of its own, and the dead-man fed with no write the drive does not need.

Every request here is taken from the samples the identification reads on the same line (issue 16 item 1: its
sample rate against what the line carries): bench/line_budget.py counts them by kind.
"""

from __future__ import annotations

from servotool.model.codec import raw_to_eng
from servotool.model.profile import Entry
from servotool.motion import deadman
from servotool.motion.jogger import Jogger
from servotool.ops.params import write_changes, write_runs

# A drive's watchdog is fed once this share of its timeout has passed (less what the caller may take before it looks
# again): a third of the timeout stays spare. A JOG beats every third of it (keepalive_interval_s).
WATCHDOG_FEED_SHARE = 2.0 / 3.0
# A caller that took longer than it said by this share of the timeout (half the spare third) stalled: from then on its
# longest gap is the lead (a step check, which says none, beat at two thirds and a 170 ms stall tripped DSX7E's 500 ms).
STALL_SPARE = (1.0 - WATCHDOG_FEED_SHARE) / 2.0


class Mover(Jogger):
    """A Jogger whose moves start from rest (start) and whose dead-man is fed by keep_alive."""

    _ends_at: float | None = None  # segment route: from then on the running move's own segment brakes it
    _looked: float | None = None  # when keep_alive was last called
    _promised_s = 0.0  # ... and the lead_s it was given then
    _late_s = 0.0  # the longest time between two calls that overran its lead: the host's own stalls, taken as a lead
    ended_itself = False  # the last command(0) found the move's own segment braking it: no stop command acted

    @property
    def folds(self) -> bool:
        """Whether start writes a move's settings in fewer requests than set_speed, set_ramp and command (the JOG
        and segment routes, whose speed is a parameter)."""
        return self.route.kind in ("trigger", "segment")

    def start(
        self,
        direction: int,
        speed_rpm: float,
        ramp_raw: int,
        stop_after_s: float | None = None,
        within_rev: float | None = None,
    ) -> None:
        """A move from rest: set_speed, set_ramp and command(direction) in the fewest requests. What changed goes in
        one verified write where the entries are adjacent (on the segment route with the move's displacement:
        IS620P's H11-12..H11-15; DSX7E's Pn512-513), and what this jogger wrote itself is not read again (IS620P
        spent six requests a move on them, DSX7E five). stop_after_s: the move accelerates that long and then stops
        (command(0)); on the segment route one segment of its own then carries it where that is within the
        dead-man's segment (SegmentMoves.length_rev), and a command(0) from then on writes nothing. within_rev: that
        segment no longer than this (the room left in the caller's travel band), so that the drive brakes the move
        inside it by itself, whenever the host looks again."""
        if not self.folds or self.direction:
            self.set_speed(speed_rpm)
            self.set_ramp(ramp_raw)
            self.command(direction)
            return
        self.speed_rpm = abs(speed_rpm)
        ramp = self._ramp_entry()
        ramp_ms = float(raw_to_eng(ramp, ramp_raw))
        if ramp_raw != self._ramp_raw or self.dead_man is None or self.speed_rpm > self.dead_man.speed_rpm:
            self.arm_dead_man(self.speed_rpm, ramp_ms)  # before anything is written
        changes = [
            (e, old, new)
            for e, old, new in (
                (self.speed_entry, self.speed_param(), self._speed_raw(self.speed_rpm)),
                (ramp, self._ramp_raw, ramp_raw),
            )
            if old != new
        ]
        if changes and self.segments is not None and direction:
            # The speed unchanged between a changed ramp and the displacement (IS620P H11-14 between H11-12/13 and
            # H11-15: a dithered cycle) goes along, so that the three go in one request instead of three.
            speed = self.speed_param()
            bridged = changes if changes[0][0] is self.speed_entry else [(self.speed_entry, speed, speed), *changes]
            fold = self._folded_distance(bridged, direction, ramp_ms, stop_after_s, within_rev)
            changes = bridged + fold if fold else changes
        for result in write_changes(self.drive, changes):
            if result.entry is self.speed_entry:
                self._speed_param_raw = result.new
            elif result.entry is ramp:
                self._ramp_raw = result.new
            elif self.segments is not None:
                self.segments.distance_written(result.new)
        if self.segments is not None:
            self.segments.own_s, self.segments.own_within = stop_after_s, within_rev
        self.command(direction)

    def _folded_distance(
        self,
        changes: list[tuple[Entry, int, int]],
        direction: int,
        ramp_ms: float,
        stop_after_s: float | None,
        within_rev: float | None,
    ) -> list[tuple[Entry, int, int]]:
        """The move's displacement as a change to write with `changes`, where it is adjacent to one of them."""
        assert self.segments is not None
        distance = self.route.entries["segment_distance"]
        raw = self.segments.distance_raw(
            direction, self.speed_rpm, self.keepalive.interval_s, ramp_ms, stop_after_s, within_rev
        )
        written = self.segments.written_distance()
        fold = (distance, raw if written is None else written, raw)
        runs = write_runs(self.drive, sorted([*changes, fold], key=lambda c: c[0].address))
        return [fold] if raw != written and any(len(run) > 1 and fold in run for run in runs) else []

    def _segment_command(self) -> None:
        segments = self.segments
        assert segments is not None
        if (
            not self.direction
            and segments.ends_itself
            and self._ends_at is not None
            and self.clock.now() >= self._ends_at
        ):
            segments.moving = 0  # the move's own segment is braking it now: nothing to write
            self.ended_itself = True
            return
        self.ended_itself = False
        own = segments.own_s if self.direction else None
        super()._segment_command()
        segments.own_s = segments.own_within = None
        self._ends_at = self.clock.now() + own if own is not None and segments.ends_itself else None

    def own_segment_rev(self) -> float | None:
        """The length (rev) of the running move's own segment, which the drive brakes by itself at its end (start with
        stop_after_s); None where the host stops the move."""
        segments = self.segments
        raw = segments.written_distance() if segments is not None else None
        if segments is None or raw is None or not segments.ends_itself or not self.direction:
            return None
        return abs(raw) / segments.units_per_rev()

    def starved(self, gap_s: float = 0.0) -> str:
        """Words for an alarm the drive's own watchdog (route drive_timeout) may have raised because the host stalled:
        where the longest gap between the caller's looks that overran its lead (keep_alive), or gap_s (one the
        caller saw itself, between its samples), outlasted the spare third of the timeout, which a beat left to the
        last moment then misses; "" otherwise."""
        timeout = self._timeout_s
        gap = max(gap_s, self._late_s)
        if self.dead_man is None or self.dead_man.route != "drive_timeout" or timeout is None or timeout <= 0:
            return ""
        if gap < (1.0 - WATCHDOG_FEED_SHARE) * timeout:
            return ""
        # A look's gap counts up to the timeout (keep_alive): one that reached it was that long or longer.
        length = (
            f"{1000 * gap:.0f} ms" if gap > self._late_s or self._late_s < timeout else f"{1000 * gap:.0f} ms or more"
        )
        return (
            f" (its host watchdog: no request for {length} against its {1000 * timeout:.0f} ms timeout; the "
            "host stalled, a busy machine?)"
        )

    def keep_alive(self, lead_s: float = 0.0) -> None:
        """Feed the dead-man with no write the drive does not need. lead_s: how long the caller may take before it
        calls again, and at least the longest it has taken where it overran that by STALL_SPARE (a busy host stalls
        between calls, and a beat left to the last moment then comes too late). A drive's watchdog (route
        drive_timeout) gets its beat at the last moment that still leaves a third of its timeout spare
        (WATCHDOG_FEED_SHARE; a beat every third, as a JOG keeps, wrote 1.6 beats a move on DSX7E at 19200). On the
        segment route a fresh segment only once the running one would end within a beat (each covers SEGMENT_BEATS
        beats at speed: re-arming it on every beat cost IS620P two writes a beat); a move's own segment ends within
        the dead-man's bound by itself (start) and is never re-armed."""
        ka, segments, timeout = self.keepalive, self.segments, self._timeout_s
        now = self.clock.now()
        if self._looked is not None and timeout and now - self._looked > self._promised_s + STALL_SPARE * timeout:
            # longer than the caller said, by half the spare: the host stalled (a gap over the timeout came before the
            # motion, or the watchdog has tripped)
            self._late_s = max(self._late_s, min(now - self._looked, timeout))
        self._looked, self._promised_s = now, lead_s
        lead_s = max(lead_s, self._late_s)
        if segments is not None and ka.entry is None:
            if (
                segments.moving
                and not segments.ends_itself
                and ka.due_after((deadman.SEGMENT_BEATS - 1.0) * ka.interval_s)
            ):
                ka.beat()
        elif (
            ka.entry is not None
            and timeout is not None
            and timeout > 0
            and self.dead_man is not None
            and self.dead_man.route == "drive_timeout"
        ):
            if ka.due_after(max(ka.interval_s, WATCHDOG_FEED_SHARE * timeout - lead_s)):
                ka.beat()
        else:
            ka.beat_if_due()
        ka.toggle_if_due()  # a watchdog relay (--heartbeat) needs its toggle every beat, writes or not
