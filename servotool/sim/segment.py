"""A relative position move of the simulated drive (the multi-segment position function's segment 1): it starts on a
start edge, runs at the segment speed with the drive's ramp, and ends and stops by itself at its end.

The move brakes so as to stop at its end, then the drive holds there (servo on). What a new start edge does during a
move is not in the manual (the firmware's trigger semantics, sim config --segment-restart): by default it waits
until the move has ended and settled, and a falling edge brakes the move.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.sim.plant import Plant

STEP_S = 0.002  # the move checks its braking point at this resolution
SETTLED_RPM = 5.0  # a braked move has ended (and settled: a queued start may act) below this speed ...
SETTLE_MAX_S = 0.1  # ... or this long after its ramp down (the hold may ring on around its end)


@dataclass
class Segment:
    """One running move: its end position and direction, and whether it is braking."""

    end_rev: float
    direction: int
    speed_rpm: float
    braking: bool = False
    braked_at: float | None = None  # when it began to brake ...
    braked_from_rps: float = 0.0  # ... from this speed (rev/s)

    @classmethod
    def start(cls, plant: Plant, distance_rev: float, speed_rpm: float) -> Segment:
        direction = (distance_rev > 0) - (distance_rev < 0)
        seg = cls(plant.position_rev + distance_rev, direction, abs(speed_rpm))
        plant.set_speed_command(direction * seg.speed_rpm)
        return seg

    def brake(self, plant: Plant) -> None:
        """Stop the move now, at the drive's ramp (it ends once at rest)."""
        self.braked_from_rps = max(abs(plant.true_speed_rpm), abs(plant.speed_command_rpm)) / 60.0
        plant.set_speed_command(0.0)
        self.braking = True
        self.braked_at = plant.time

    def advance(self, plant: Plant, now: float, ramp_rev_s2: float) -> bool:
        """Integrate up to now, braking in time to stop at the end; True once the move has ended at rest."""
        t = plant.time
        while t < now:
            t = min(now, t + STEP_S)
            plant.advance_to(t)
            if not self.braking:
                speed = abs(plant.true_speed_rpm) / 60.0
                command = abs(plant.speed_command_rpm) / 60.0
                v = max(speed, command)
                left = (self.end_rev - plant.position_rev) * self.direction
                # the ramp's stopping distance, with one check step of look-ahead and the loop's lag
                if self.direction == 0 or left - v * 3 * STEP_S <= v * v / (2.0 * ramp_rev_s2):
                    self.brake(plant)
            elif (abs(plant.true_speed_rpm) < SETTLED_RPM and abs(plant.speed_command_rpm) < SETTLED_RPM) or (
                self.braked_at is not None and t - self.braked_at > self.braked_from_rps / ramp_rev_s2 + SETTLE_MAX_S
            ):
                return True  # positioning complete: the hold's own correction (a rpm or two) is not the move
        return False
