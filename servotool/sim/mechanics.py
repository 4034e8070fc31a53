"""The simulated machine's mechanics: a rigid load, or a load behind a compliant coupling, with gravity and cogging.

Off by default (rigid, no arm, no cogging), when the plant moves exactly as before. Mechanics outside the rigid
model (the estimator's model) are here so identification can be tried on them:

- compliant coupling (two-mass): motor side Jm, load side JL = Jm * load_ratio, joined by a spring k and a damper c
  chosen so the motor-side resonance (torque to motor speed) is at resonance_hz with damping ratio
  resonance_damping: k = (2 pi f)^2 * Jr, c = 2 zeta (2 pi f) * Jr with Jr = Jm JL / (Jm + JL). The antiresonance
  sits at f / sqrt(1 + load_ratio). The drive sees the motor side only (encoder on the motor).
- backlash: a dead zone of backlash_rad (at the motor shaft) in the coupling; inside it no torque passes. Without a
  resonance the flanks meet through a stiff contact (CONTACT_HZ, CONTACT_DAMPING). The contact only pushes.
- arm gravity: a load torque A * rated * sin(theta_load / gear + phase) (positive opposes positive speed), an arm
  through a gear of ratio `gear`; with phase 0 the arm hangs down at position 0.
- cogging: a motor-side torque C * rated * sin(periods * theta_motor).

With a coupling, friction (Coulomb, stiction, viscous), the constant load torque and the arm act on the load side
(guides and bearings of the load: what makes backlash lost motion), cogging and the holding brake on the motor.
Integration is semi-implicit Euler, substepped so the spring's angular frequency times the step stays below
MAX_OMEGA_STEP (stable up to 2, accurate to about 0.1 %/cycle in frequency at 0.1).
The coupling's state is its deflection (motor minus load angle) and its rate; both are 0 on a rigid load, so a
state saved while rigid is valid when a coupling is configured later.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

CONTACT_HZ = 150.0  # stiffness of a backlash's flanks when no compliant coupling is configured
CONTACT_DAMPING = 0.5
MAX_OMEGA_STEP = 0.1
REST_RATE = 1e-6  # rad/s: a coupling moving slower than this counts as settled
REST_TORQUE = 1e-6  # N*m


@dataclass(frozen=True)
class MechanicsSettings:
    """Mechanics beyond the rigid load (all 0: rigid, the estimator's model)."""

    resonance_hz: float = 0.0  # 0 = rigid coupling
    resonance_damping: float = 0.05
    backlash_rad: float = 0.0  # dead zone at the motor shaft
    arm_nm: float = 0.0  # arm gravity amplitude, N*m
    gear: float = 1.0
    arm_phase_rad: float = 0.0
    cogging_nm: float = 0.0
    cogging_periods: int = 6

    @classmethod
    def from_sim(cls, s: Mapping[str, float | int], rated_nm: float) -> MechanicsSettings:
        """From the simulated drive's settings (sim config: fractions of rated torque, degrees)."""
        return cls(
            resonance_hz=float(s["resonance_hz"]),
            resonance_damping=float(s["resonance_damping"]),
            backlash_rad=float(s["backlash_rad"]),
            arm_nm=float(s["arm_gravity"]) * rated_nm,
            gear=float(s["gear"]),
            arm_phase_rad=math.radians(float(s["arm_angle"])),
            cogging_nm=float(s["cogging"]) * rated_nm,
            cogging_periods=int(s["cogging_periods"]),
        )

    @property
    def coupled(self) -> bool:
        return self.resonance_hz > 0 or self.backlash_rad > 0


@dataclass(frozen=True)
class Friction:
    """What resists the load: Coulomb (with stiction) and viscous friction, and a constant load torque (N*m,
    N*m*s/rad; positive opposes positive speed)."""

    coulomb: float
    viscous: float
    load_nm: float


@dataclass
class MotorState:
    """The mechanical state the plant integrates (motor angle and speed, the coupling's deflection and rate)."""

    w: float
    theta: float
    defl: float = 0.0
    defl_rate: float = 0.0


class Mechanics:
    """One step of the machine's motion under the motor torque, for given inertias, friction and mechanics."""

    def __init__(self, jm: float, load_ratio: float, m: MechanicsSettings) -> None:
        self.m = m
        self.j_total = jm * (1.0 + load_ratio)
        self.coupled = m.coupled and load_ratio > 0
        self.jm, self.jl = (jm, jm * load_ratio) if self.coupled else (self.j_total, 0.0)
        self.k = self.c = 0.0
        self.substeps = 1
        if self.coupled:
            jr = self.jm * self.jl / (self.jm + self.jl)
            hz, zeta = (m.resonance_hz, m.resonance_damping) if m.resonance_hz > 0 else (CONTACT_HZ, CONTACT_DAMPING)
            omega = 2 * math.pi * hz
            self.k, self.c = omega * omega * jr, 2 * zeta * omega * jr
            self.omega = omega
        self._half_gap = m.backlash_rad / 2

    def substeps_for(self, step_s: float) -> int:
        return max(1, math.ceil(self.omega * step_s / MAX_OMEGA_STEP)) if self.coupled else 1

    def arm_nm(self, theta_load: float) -> float:
        m = self.m
        return m.arm_nm * math.sin(theta_load / m.gear + m.arm_phase_rad) if m.arm_nm else 0.0

    def cogging_nm(self, theta: float) -> float:
        m = self.m
        return m.cogging_nm * math.sin(m.cogging_periods * theta) if m.cogging_nm else 0.0

    def coupling_nm(self, defl: float, rate: float) -> float:
        """Torque the coupling passes from motor to load (positive pushes the load forward)."""
        gap = self._half_gap
        if gap <= 0:
            return self.k * defl + self.c * rate
        if abs(defl) <= gap:
            return 0.0
        torque = self.k * (defl - math.copysign(gap, defl)) + self.c * rate
        return torque if (torque > 0) == (defl > 0) else 0.0  # the flanks push, they do not pull apart

    def rigid_extra_nm(self, theta: float) -> float:
        """Position-dependent load torque on a rigid load (opposing positive speed)."""
        return self.arm_nm(theta) + self.cogging_nm(theta)

    def step_coupled(self, s: MotorState, motor_nm: float, brake: float, friction: Friction, step_s: float) -> None:
        """Advance a two-mass machine by step_s (substepped); motor_nm is the motor's torque, brake the holding
        brake's on the motor shaft (0 when open)."""
        n = self.substeps_for(step_s)
        h = step_s / n
        for _ in range(n):
            w_load = s.w - s.defl_rate
            spring = self.coupling_nm(s.defl, s.defl_rate)
            w_new = friction_step(s.w, motor_nm - self.cogging_nm(s.theta) - spring, brake, self.jm, h)
            on_load = spring - friction.load_nm - self.arm_nm(s.theta - s.defl) - friction.viscous * w_load
            w_load = friction_step(w_load, on_load, friction.coulomb, self.jl, h)
            s.theta += w_new * h
            s.defl += (w_new - w_load) * h
            s.w, s.defl_rate = w_new, w_new - w_load

    def at_rest(self, s: MotorState, brake: float, friction: Friction) -> bool:
        """Nothing moves and nothing will with the motor unpowered (the plant may skip integrating)."""
        if s.w != 0.0:
            return False
        if not self.coupled:
            return abs(friction.load_nm + self.rigid_extra_nm(s.theta)) <= friction.coulomb + brake
        if abs(s.defl_rate) > REST_RATE:
            return False
        spring = self.coupling_nm(s.defl, 0.0)
        return (
            abs(spring - friction.load_nm - self.arm_nm(s.theta - s.defl)) <= friction.coulomb + REST_TORQUE
            and abs(spring + self.cogging_nm(s.theta)) <= brake + REST_TORQUE
        )


def friction_step(w: float, torque: float, coulomb: float, j: float, h: float) -> float:
    """The speed after h under a torque (friction aside) and Coulomb friction with stiction at rest: friction
    holds a motor at rest against up to its value, and stops a moving one rather than reversing it."""
    if w == 0.0:
        if abs(torque) <= coulomb:
            return 0.0  # stiction (or the brake) holds
        return w + (torque - math.copysign(coulomb, torque)) / j * h
    w_new = w + (torque - math.copysign(coulomb, w)) / j * h
    if (w_new > 0) != (w > 0):  # friction stops the motor, it does not reverse it
        w_new = 0.0 if abs(torque) <= coulomb else w_new
    return w_new
