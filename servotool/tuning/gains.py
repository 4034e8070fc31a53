"""Gain suggestions from the identified inertia and a rigidity level (or an explicit speed-loop bandwidth).

Rules (one bandwidth f, in Hz, sets everything; they are the usual cascade rules of thumb, each loop a factor of
about 4 away from its neighbour so the loops do not fight):

- speed loop gain: f in Hz, the common drive parameter that means bandwidth once the inertia ratio is set;
  the absolute proportional gain is Kp = 2*pi*f*J_total (N*m per rad/s).
- speed integral time: Ti = 4 / (2*pi*f), the PI zero a quarter of the bandwidth below it.
- position loop gain: Kpp = 2*pi*f / 4 (1/s), the position bandwidth a quarter of the speed bandwidth.
- torque filter: tau = 1 / (2*pi*4*f), the filter corner four times above the speed bandwidth.

Rigidity levels 1..31 map geometrically onto 1 Hz .. 400 Hz: f(r) = 400**((r - 1) / 30), rounded to 0.1 Hz
(1.0, 1.2, 1.5, 1.8, 2.2, ... 327.6, 400.0). Which level a machine stands depends on its mechanics (belts and
long couplings want low levels, stiff direct drives high ones); the table only fixes the scale.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

RIGIDITY_MIN = 1
RIGIDITY_MAX = 31
RIGIDITY_BANDWIDTH_HZ: tuple[float, ...] = tuple(
    round(400.0 ** ((r - RIGIDITY_MIN) / (RIGIDITY_MAX - RIGIDITY_MIN)), 1)
    for r in range(RIGIDITY_MIN, RIGIDITY_MAX + 1))
"""Speed-loop bandwidth in Hz for rigidity 1..31 (index 0 is rigidity 1)."""

BANDWIDTH_MIN_HZ = 0.1
BANDWIDTH_MAX_HZ = 1000.0
"""Explicit bandwidths outside this range are refused: beyond 1 kHz is above any drive's current loop."""

INTEGRAL_FACTOR = 4.0
POSITION_FACTOR = 4.0
TORQUE_FILTER_FACTOR = 4.0


@dataclass(frozen=True)
class GainSuggestion:
    """Suggested gains. Values are unrounded; round to each parameter's scale when writing them."""

    bandwidth_hz: float
    """Speed-loop bandwidth the suggestion is built on."""
    rigidity: int | None
    """The rigidity level used, or None when an explicit bandwidth was given."""
    j_total_kgm2: float
    load_ratio: float
    """J_load / J_motor used for the suggestion (what the drive's inertia-ratio parameter must hold)."""
    speed_loop_gain_hz: float
    speed_kp_nm_s_per_rad: float
    """Absolute proportional speed gain 2*pi*f*J_total."""
    speed_integral_ms: float
    position_loop_gain_per_s: float
    torque_filter_ms: float


def rigidity_bandwidth_hz(rigidity: int) -> float:
    """Speed-loop bandwidth (Hz) of a rigidity level 1..31."""
    if isinstance(rigidity, bool) or not isinstance(rigidity, int):
        raise ValueError(f"rigidity must be an integer {RIGIDITY_MIN}..{RIGIDITY_MAX}, got {rigidity!r}")
    if not RIGIDITY_MIN <= rigidity <= RIGIDITY_MAX:
        raise ValueError(f"rigidity must be {RIGIDITY_MIN}..{RIGIDITY_MAX}, got {rigidity}")
    return RIGIDITY_BANDWIDTH_HZ[rigidity - RIGIDITY_MIN]


def suggest_gains(*, rotor_inertia_kgcm2: float, load_ratio: float | None = None, j_total_kgm2: float | None = None,
                  rigidity: int | None = None, bandwidth_hz: float | None = None) -> GainSuggestion:
    """Gains for a rigidity level or an explicit bandwidth; give exactly one of load_ratio / j_total_kgm2 and
    exactly one of rigidity / bandwidth_hz. Raises ValueError with the reason for nonsense input."""
    if not (_finite(rotor_inertia_kgcm2) and rotor_inertia_kgcm2 > 0):
        raise ValueError(f"rotor inertia must be a positive number of kg*cm^2, got {rotor_inertia_kgcm2!r}")
    jm = rotor_inertia_kgcm2 * 1e-4
    if (load_ratio is None) == (j_total_kgm2 is None):
        raise ValueError("give exactly one of load_ratio and j_total_kgm2")
    if load_ratio is not None:
        if not (_finite(load_ratio) and load_ratio >= 0):
            raise ValueError(f"load ratio (J_load/J_motor) must be a number >= 0, got {load_ratio!r}")
        ratio = float(load_ratio)
        j_total = jm * (1.0 + ratio)
    else:
        assert j_total_kgm2 is not None
        if not (_finite(j_total_kgm2) and j_total_kgm2 > 0):
            raise ValueError(f"total inertia must be a positive number of kg*m^2, got {j_total_kgm2!r}")
        # Allow a hair below J_motor (identification noise on a bare motor), not a real deficit.
        if j_total_kgm2 < 0.95 * jm:
            raise ValueError(f"total inertia {j_total_kgm2:.4g} kg*m^2 is below the rotor inertia {jm:.4g} kg*m^2; "
                             "check the motor data or repeat the identification")
        j_total = max(float(j_total_kgm2), jm)
        ratio = j_total / jm - 1.0

    if (rigidity is None) == (bandwidth_hz is None):
        raise ValueError("give exactly one of rigidity and bandwidth_hz")
    if rigidity is not None:
        f = rigidity_bandwidth_hz(rigidity)
    else:
        assert bandwidth_hz is not None
        if not (_finite(bandwidth_hz) and BANDWIDTH_MIN_HZ <= bandwidth_hz <= BANDWIDTH_MAX_HZ):
            raise ValueError(f"bandwidth must be {BANDWIDTH_MIN_HZ:g}..{BANDWIDTH_MAX_HZ:g} Hz, got {bandwidth_hz!r}")
        f = float(bandwidth_hz)

    wc = 2.0 * math.pi * f
    return GainSuggestion(
        bandwidth_hz=f, rigidity=rigidity, j_total_kgm2=j_total, load_ratio=ratio,
        speed_loop_gain_hz=f, speed_kp_nm_s_per_rad=wc * j_total,
        speed_integral_ms=1000.0 * INTEGRAL_FACTOR / wc,
        position_loop_gain_per_s=wc / POSITION_FACTOR,
        torque_filter_ms=1000.0 / (TORQUE_FILTER_FACTOR * wc))


def _finite(x: object) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(float(x))
