"""Gain suggestions in each drive's own terms: its rigidity levels on its own range, anchored at its factory gains.

No manual servotool has prints a level -> gain table (SD25's was an image lost in extraction; IS620P, DSX7E and SDC
print none), so a level's gains are the drive's factory gains scaled about the factory level: each level up is
LEVEL_STEP (2^(1/4): four levels per doubling, the spacing of vendors' published tables) times the bandwidth of the
one below. The speed-loop gain (Hz, which is bandwidth once the inertia ratio is set) and the position gain scale with
the bandwidth; the integral time and the torque-filter time constant scale inversely. So every level keeps the
factory's own ratios: the PI zero where the factory puts it, the position loop as far below the speed loop, and the
torque filter 8-10x above the bandwidth (IS620P 8x, DSX7E 10.5x at their defaults).

A drive without a rigidity parameter (SDC: its panel function F3 has levels 0..19, factory 10, and no register,
sdc.md section 4) gets the levels of F3 around its factory gains; the level itself is not written there.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from servotool.model.gain_units import to_canonical
from servotool.model.profile import Entry, Profile

LEVEL_STEP = 2.0**0.25
PANEL_LEVELS = (0, 19, 10)  # (lowest, highest, factory) where the drive has no rigidity parameter: SDC's F3
BANDWIDTH_MIN_HZ = 0.1
BANDWIDTH_MAX_HZ = 1000.0
"""Explicit bandwidths outside this range are refused: beyond 1 kHz is above any drive's current loop."""
GENERIC_FACTORY = (40.0, 20.0, 40.0, 0.5)
FILTER_FACTOR_MIN = 8.0
"""The torque filter's corner at least this many times the bandwidth: IS620P's and DSX7E's factory placement (8x,
10.5x); SD25's factory filter is a placeholder (the manual prints '-') and SDC's PN50 (100 Hz at a 200 Hz gain) is a
panel value below its own speed gain."""  # speed Hz, integral ms, position 1/s, filter ms: a profile without them


@dataclass(frozen=True)
class LoopGains:
    """The four loop gains in canonical units (see model.gain_units)."""

    speed_hz: float
    integral_ms: float
    position_per_s: float
    filter_ms: float

    def scaled(self, factor: float) -> LoopGains:
        """The same ratios at factor x the speed-loop bandwidth (the filter at least FILTER_FACTOR_MIN above)."""
        speed = self.speed_hz * factor
        filter_ms = min(self.filter_ms / factor, 1000.0 / (2 * math.pi * FILTER_FACTOR_MIN * speed))
        return LoopGains(speed, self.integral_ms / factor, self.position_per_s * factor, filter_ms)


@dataclass(frozen=True)
class RigidityScale:
    """One drive's rigidity levels: level N's gains are the factory gains scaled by LEVEL_STEP**(N - factory)."""

    lowest: int
    highest: int
    factory_level: int
    factory: LoopGains
    parameter: Entry | None  # the drive's rigidity parameter (written with the gains); None: not writable

    def check(self, level: object) -> int:
        if isinstance(level, bool) or not isinstance(level, int) or not self.lowest <= level <= self.highest:
            raise ValueError(
                f"rigidity must be {self.lowest}..{self.highest} (this drive's own levels, factory "
                f"{self.factory_level}), got {level!r}"
            )
        return level

    def factor(self, level: int) -> float:
        return float(LEVEL_STEP ** (self.check(level) - self.factory_level))

    def bandwidth_hz(self, level: int) -> float:
        return self.factory.speed_hz * self.factor(level)

    def level_at(self, bandwidth_hz: float) -> int:
        """The level nearest to a bandwidth (clamped to the range)."""
        n = self.factory_level + round(math.log(bandwidth_hz / self.factory.speed_hz, LEVEL_STEP))
        return max(self.lowest, min(self.highest, n))


def _factory(profile: Profile, role: str, fallback: float) -> float:
    entry = profile.role(role)
    if entry is None or entry.default is None:
        return fallback
    value = to_canonical(role, entry, entry.default * entry.scale)
    return value if value > 0 else fallback


def rigidity_scale(profile: Profile) -> RigidityScale:
    """The profile's levels (its rigidity parameter's range and default, else PANEL_LEVELS) and factory gains."""
    s, i, p, f = GENERIC_FACTORY
    factory = LoopGains(
        _factory(profile, "speed_loop_gain", s),
        _factory(profile, "speed_loop_integral", i),
        _factory(profile, "position_loop_gain", p),
        _factory(profile, "torque_filter", f),
    )
    entry = profile.role("rigidity")
    if entry is None:
        return RigidityScale(*PANEL_LEVELS, factory, None)
    lo, hi = round(entry.min * entry.scale), round(entry.max * entry.scale)
    default = round((entry.default if entry.default is not None else entry.min) * entry.scale)
    return RigidityScale(lo, hi, default, factory, entry)


@dataclass(frozen=True)
class GainSuggestion:
    """Suggested gains. Values are unrounded; round to each parameter's scale when writing them."""

    bandwidth_hz: float
    """Speed-loop bandwidth the suggestion is built on."""
    rigidity: int | None
    """The drive's own rigidity level used, or None when an explicit bandwidth was given."""
    j_total_kgm2: float
    load_ratio: float
    """J_load / J_motor used for the suggestion (what the drive's inertia-ratio parameter must hold)."""
    speed_loop_gain_hz: float
    speed_kp_nm_s_per_rad: float
    """Absolute proportional speed gain 2*pi*f*J_total."""
    speed_integral_ms: float
    position_loop_gain_per_s: float
    torque_filter_ms: float

    @property
    def loop(self) -> LoopGains:
        return LoopGains(
            self.speed_loop_gain_hz, self.speed_integral_ms, self.position_loop_gain_per_s, self.torque_filter_ms
        )


def suggest_gains(
    *,
    rotor_inertia_kgcm2: float,
    scale: RigidityScale,
    load_ratio: float | None = None,
    j_total_kgm2: float | None = None,
    rigidity: int | None = None,
    bandwidth_hz: float | None = None,
) -> GainSuggestion:
    """Gains at a level of the drive's scale or at an explicit bandwidth (with the factory's ratios); give exactly
    one of load_ratio / j_total_kgm2 and of rigidity / bandwidth_hz. Raises ValueError with the reason."""
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
            raise ValueError(
                f"total inertia {j_total_kgm2:.4g} kg*m^2 is below the rotor inertia {jm:.4g} kg*m^2; "
                "check the motor data or repeat the identification"
            )
        j_total = max(float(j_total_kgm2), jm)
        ratio = j_total / jm - 1.0
    if (rigidity is None) == (bandwidth_hz is None):
        raise ValueError("give exactly one of rigidity and bandwidth_hz")
    if rigidity is not None:
        loop = scale.factory.scaled(scale.factor(rigidity))
    else:
        if not (_finite(bandwidth_hz) and BANDWIDTH_MIN_HZ <= float(bandwidth_hz) <= BANDWIDTH_MAX_HZ):  # type: ignore[arg-type]
            raise ValueError(f"bandwidth must be {BANDWIDTH_MIN_HZ:g}..{BANDWIDTH_MAX_HZ:g} Hz, got {bandwidth_hz!r}")
        loop = scale.factory.scaled(float(bandwidth_hz) / scale.factory.speed_hz)  # type: ignore[arg-type]
    f = loop.speed_hz
    return GainSuggestion(
        bandwidth_hz=f,
        rigidity=rigidity,
        j_total_kgm2=j_total,
        load_ratio=ratio,
        speed_loop_gain_hz=f,
        speed_kp_nm_s_per_rad=2.0 * math.pi * f * j_total,
        speed_integral_ms=loop.integral_ms,
        position_loop_gain_per_s=loop.position_per_s,
        torque_filter_ms=loop.filter_ms,
    )


def _finite(x: object) -> bool:
    return isinstance(x, numbers.Real) and not isinstance(x, bool) and math.isfinite(float(x))
