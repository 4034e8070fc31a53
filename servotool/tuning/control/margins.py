"""Phase and gain margins of a drive's cascade for given gains and the identified inertia, before they are written.

Loop structure (the usual servo drive's, and the simulator's): a speed PI Kp(1 + 1/(Ti s)) with Kp = 2 pi f J_conf
(J_conf: the inertia the drive is configured for), a computation delay of one control period plus half a period for
the encoder's difference speed, the torque-command filter, the current loop's lag, the rigid plant 1/(J s + B), and a
low-pass on the speed feedback. The position loop (P, Kpp) closes around the closed speed loop. Margins are read off
the open-loop frequency responses on a log grid: phase margin at the first gain crossover, gain margin at the first
-180 degree crossing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.polynomial import polynomial as P

from servotool.tuning.control.gains import LoopGains

CONTROL_PERIOD_S = 125e-6  # speed-loop period of the drives modelled (8 kHz; the simulator's)
SPEED_FILTER_S = 0.25e-3  # speed-feedback low-pass
CURRENT_LOOP_S = 0.2e-3  # current loop's lag (about 800 Hz)
MIN_PHASE_DEG = 45.0
MIN_GAIN_DB = 6.0
_W = 2 * math.pi * np.logspace(-2, 4, 3000)  # 0.01 Hz .. 10 kHz


@dataclass(frozen=True)
class Margins:
    speed_phase_deg: float
    speed_gain_db: float
    crossover_hz: float
    position_phase_deg: float
    position_gain_db: float

    @property
    def phase_deg(self) -> float:
        return min(self.speed_phase_deg, self.position_phase_deg)

    @property
    def gain_db(self) -> float:
        return min(self.speed_gain_db, self.position_gain_db)

    def ok(self, min_phase: float = MIN_PHASE_DEG, min_gain: float = MIN_GAIN_DB) -> bool:
        return self.phase_deg >= min_phase and self.gain_db >= min_gain

    def describe(self) -> str:
        gm = "inf" if math.isinf(self.gain_db) else f"{self.gain_db:.1f}"
        return (
            f"phase margin {self.phase_deg:.0f}°, gain margin {gm} dB (speed loop crossover {self.crossover_hz:.1f} Hz)"
        )


def _read(L: np.ndarray) -> tuple[float, float, float]:
    """(phase margin deg, gain margin dB, crossover Hz) of an open-loop response on _W."""
    mag = np.abs(L)
    phase = np.degrees(np.unwrap(np.angle(L)))
    phase -= 360.0 * round((phase[0] + 90.0) / 360.0)  # low frequencies: -90 (P) .. -180 (PI): no 360 offset
    below = np.nonzero(mag < 1.0)[0]
    if len(below) == 0 or below[0] == 0:
        pm, wc = (math.inf if len(below) else -math.inf), 0.0
    else:
        k = int(below[0])
        pm, wc = float(180.0 + phase[k]), float(_W[k] / (2 * math.pi))
    top = int(np.argmax(phase))  # a PI's low-frequency -180 is conditional stability, not the margin
    under = top + np.nonzero(phase[top:] <= -180.0)[0]
    gm = math.inf if len(under) == 0 else float(-20.0 * math.log10(max(mag[int(under[0])], 1e-12)))
    return pm, gm, wc


def margins(
    gains: LoopGains, j_total_kgm2: float, j_configured_kgm2: float | None = None, viscous_nm_per_rad_s: float = 0.0
) -> Margins:
    """The margins of the speed and position loops with these gains on this inertia (J_conf: the drive's
    configured inertia, default the identified one, as once the ratio is written)."""
    s = 1j * _W
    j_conf = j_total_kgm2 if j_configured_kgm2 is None else j_configured_kgm2
    kp = 2 * math.pi * gains.speed_hz * j_conf
    ti = max(gains.integral_ms, 0.1) / 1000.0
    pi = kp * (1 + 1 / (ti * s))
    forward = np.exp(-1.5 * CONTROL_PERIOD_S * s) / (1 + gains.filter_ms / 1000.0 * s) / (1 + CURRENT_LOOP_S * s)
    plant = 1 / (j_total_kgm2 * s + viscous_nm_per_rad_s)
    feedback = 1 / (1 + SPEED_FILTER_S * s)
    speed_open = pi * forward * plant * feedback
    spm, sgm, wc = _read(speed_open)
    if spm <= 0 or sgm <= 0:  # an unstable speed loop: no position loop closes around it
        return Margins(spm, sgm, wc, spm, sgm)
    closed = pi * forward * plant / (1 + speed_open)
    ppm, pgm, _ = _read(gains.position_per_s / s * closed)
    return Margins(spm, sgm, wc, ppm, pgm)


def least_damping(gains: LoopGains, j_total_kgm2: float, j_configured_kgm2: float, position: bool = True) -> float:
    """The smallest damping ratio among the closed loop's poles (negative: an oscillation that grows), for the same
    structure as margins() with the delay as a first-order Pade term. position=True: the position loop closed
    around the speed loop (a position hold); False: the speed loop alone. Unlike the margins read at the first
    crossover, the poles also catch a position loop crossing a resonant speed loop's peak."""
    kp = 2 * math.pi * gains.speed_hz * j_configured_kgm2
    ti = max(gains.integral_ms, 0.1) / 1000.0
    tau = 1.5 * CONTROL_PERIOD_S
    lags = P.polymul(P.polymul([1.0, gains.filter_ms / 1000.0], [1.0, CURRENT_LOOP_S]), [1.0, tau / 2])
    # Ti s (PI) * J s (plant) * lags * speed filter + Kp (Ti s + 1) * delay numerator [* the position path]
    left = P.polymul(P.polymul(lags, [0.0, 0.0, ti * j_total_kgm2]), [1.0, SPEED_FILTER_S])
    right = P.polymul([1.0, ti], [1.0, -tau / 2]) * kp
    if position:
        left = P.polymul(left, [0.0, 1.0])
        right = P.polymul(right, [gains.position_per_s, gains.position_per_s * SPEED_FILTER_S + 1.0])
    roots = np.roots(P.polyadd(left, right)[::-1])
    return float(min(-r.real / abs(r) for r in roots if abs(r) > 0))
