"""Drive-side offline inertia identification: a torque-driven back-and-forth move timed on the plant.

The drive accelerates forward at a fixed torque up to a top speed, brakes to standstill, does the same in reverse,
and takes the inertia from torque * time / speed change of each of the four phases. Accel and decel estimates
average out Coulomb friction.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields
from enum import Enum

from servotool.sim.plant import Plant

STEP_S = 0.002  # phase switches are found to this resolution
PHASES = 4  # accel fwd, decel fwd, accel rev, decel rev
MAX_TOP_RPM = 600.0


class Progress(Enum):
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"  # travelled too far, or the plant latched an alarm


@dataclass
class Identification:
    """Identification in progress (JSON-safe through stored()/from_stored(), to carry it to another process)."""

    torque_pct: float
    max_rev: float
    top_rpm: float
    start_pos: float
    phase: int = 0  # 0 accel fwd, 1 decel fwd, 2 accel rev, 3 decel rev, 4 done
    phase_t0: float = 0.0
    phase_w0: float = 0.0
    estimates: list[float] = field(default_factory=list)  # inertia per finished phase, kg*m^2

    @classmethod
    def start(
        cls, plant: Plant, torque_pct: float, max_rev: float, rated_speed_rpm: float, now: float
    ) -> Identification:
        """Begin on the plant: torque mode, driving forward."""
        ident = cls(torque_pct, max_rev, min(MAX_TOP_RPM, rated_speed_rpm / 3), plant.position_rev, phase_t0=now)
        plant.set_mode("torque")
        plant.set_torque_command(torque_pct)
        return ident

    def advance(self, plant: Plant, now: float) -> Progress:
        """Integrate the plant up to now in small slices, switching phase when the speed crosses its targets."""
        t = plant.time
        while t < now:
            t = min(now, t + STEP_S)
            plant.advance_to(t)
            w = plant.true_speed_rpm
            if abs(plant.position_rev - self.start_pos) > self.max_rev or plant.alarm is not None:
                return Progress.FAILED
            if self.phase in (0, 2) and abs(w) >= self.top_rpm:
                self._phase_done(plant, t, w, next_torque=-self.torque_pct if self.phase == 0 else self.torque_pct)
            elif self.phase in (1, 3) and (w <= 0 if self.phase == 1 else w >= 0):
                self._phase_done(plant, t, w, next_torque=-self.torque_pct if self.phase == 1 else 0.0)
                if self.phase == PHASES:
                    return Progress.DONE
        return Progress.RUNNING

    def _phase_done(self, plant: Plant, t: float, w: float, next_torque: float) -> None:
        dt = t - self.phase_t0
        dw = abs(w - self.phase_w0) * 2 * math.pi / 60
        if dt > 0 and dw > 0:
            torque_nm = self.torque_pct / 100 * plant.motor.rated_torque_nm
            self.estimates.append(torque_nm * dt / dw)
        self.phase += 1
        self.phase_t0 = t
        self.phase_w0 = w
        plant.set_torque_command(next_torque)

    def load_ratio(self, rotor_inertia_kgcm2: float) -> float | None:
        """Load inertia / motor inertia from the phases' estimates; None without an estimate from every phase."""
        if len(self.estimates) < PHASES:
            return None
        return sum(self.estimates) / len(self.estimates) / (rotor_inertia_kgcm2 * 1e-4) - 1.0

    def stored(self) -> dict[str, object]:
        return asdict(self)

    @classmethod
    def from_stored(cls, raw: object, shift: float) -> Identification | None:
        """From stored(), its times moved into this process's clock by shift; None when unusable."""
        if not isinstance(raw, dict):
            return None
        try:
            ident = cls(**{f.name: raw[f.name] for f in fields(cls) if f.name in raw})
            ident.phase_t0 = float(ident.phase_t0) + shift
            ident.estimates = [float(x) for x in ident.estimates or []]
        except (TypeError, ValueError):
            return None
        return ident
