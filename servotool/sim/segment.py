"""A relative position move of the simulated drive (the multi-segment position function's segment 1): it starts on a
start edge, runs at the segment speed with the drive's ramp, and ends and stops by itself at its end.

Exactly what the profile's dead_man route documents: a new start edge during a move starts a fresh segment from the
present position; the move brakes so as to stop at its end, then the drive holds there (servo on).
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.sim.plant import Plant

STEP_S = 0.002  # the move checks its braking point at this resolution


@dataclass
class Segment:
    """One running move: its end position and direction, and whether it is braking."""

    end_rev: float
    direction: int
    speed_rpm: float
    braking: bool = False

    @classmethod
    def start(cls, plant: Plant, distance_rev: float, speed_rpm: float) -> Segment:
        direction = (distance_rev > 0) - (distance_rev < 0)
        seg = cls(plant.position_rev + distance_rev, direction, abs(speed_rpm))
        plant.set_speed_command(direction * seg.speed_rpm)
        return seg

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
                    plant.set_speed_command(0.0)
                    self.braking = True
            elif abs(plant.true_speed_rpm) < 1.0 and abs(plant.speed_command_rpm) < 1.0:
                return True
        return False
