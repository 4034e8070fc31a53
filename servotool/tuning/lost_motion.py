"""Where a coupling with backlash may leave the motor turning alone (tuning.consistency's lost-motion check).

Where the torque through the coupling reverses (a move's braking after its acceleration, a start against the flank
the last stop left), the motor crosses the gap alone: it needs only its own inertia's torque, while the load coasts
on, slowed by its friction, until the other flank takes it up. Windows there read J far low, and with them the
friction the fit shares with every window (IS620P, backlash 0.2 rad at ratio 2: J 5 % low in every subset alike,
the accelerating windows through an inflated Coulomb term). An observer follows the load through a dead zone behind
the measured motor speed, with the load's inertia and friction from the rigid fit, and marks the sampling
intervals in which the motor and the load may not have turned together; the gap it assumes is small, and the
windows it keeps clear of stay clear by a margin, so a larger gap's lost motion falls inside the marked spans too
(the windows clear of them gave J within 0.3 % at 0.05-0.2 rad of backlash for an assumed 0.05 rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GAP_RAD = 0.05            # the dead zone the observer assumes (at the motor shaft)
MARGIN_INTERVALS = 1      # sampling intervals kept clear on both sides of a marked span
STEP_S = 1e-3             # the observer's integration step (a crossing lasts tens of ms)


@dataclass(frozen=True)
class LoadSide:
    """The load as the rigid fit sees it: inertia beyond the motor's and what slows it (N*m, N*m*s/rad)."""

    inertia: float
    coulomb: float
    viscous: float
    load_torque: float

    def drag(self, w: float) -> float:
        """The torque that slows the load (positive opposes positive speed); none from Coulomb at standstill."""
        return self.coulomb * _sign(w) + self.viscous * w + self.load_torque


def _sign(v: float) -> int:
    return (v > 0) - (v < 0)


def coupled_intervals(t: np.ndarray, w: np.ndarray, load: LoadSide, gap: float = GAP_RAD) -> np.ndarray:
    """Per sampling interval, whether the motor and the load stayed in contact through all of it (motor speed w
    in rad/s, linear between samples). The load starts in the middle of the gap: where it rests is unknown."""
    half = gap / 2.0
    defl, w_load, contact = 0.0, float(w[0]), False
    out = np.zeros(max(0, t.size - 1), dtype=bool)
    if load.inertia <= 0:
        return ~out
    for i in range(t.size - 1):
        span = float(t[i + 1] - t[i])
        steps = max(1, math.ceil(span / STEP_S))
        dt = span / steps
        w0, accel = float(w[i]), float(w[i + 1] - w[i]) / span
        held = contact
        for k in range(steps):
            w_motor = w0 + accel * (k + 0.5) * dt
            # In contact the flank must push the load along: a torque of the wrong sign lets it go.
            if contact and (load.inertia * accel + load.drag(w_motor)) * _sign(defl) < 0:
                contact = False
            if not contact:
                coasting = w_load - load.drag(w_load) / load.inertia * dt
                if _sign(coasting) != _sign(w_load) and abs(load.load_torque) < load.coulomb:
                    coasting = 0.0              # friction stops the load; it does not turn it back
                w_load = coasting
                defl += (w_motor - w_load) * dt
                if abs(defl) >= half:
                    defl, contact, w_load = math.copysign(half, defl), True, w_motor
            held = held and contact
        out[i] = held
    return out


def clear_windows(starts: np.ndarray, ends: np.ndarray, coupled: np.ndarray,
                  margin: int = MARGIN_INTERVALS) -> np.ndarray:
    """The windows [starts, ends] (sample indices) whose intervals, and margin intervals either side, all stayed
    coupled."""
    loose = np.concatenate(([0], np.cumsum(~coupled)))
    lo = np.clip(starts - margin, 0, coupled.size)
    hi = np.clip(ends + margin, 0, coupled.size)
    return (loose[hi] - loose[lo]) == 0
