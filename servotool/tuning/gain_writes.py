"""Turning an identified inertia into the drive's inertia-ratio, gain and rigidity parameter values, with margins.

Before anything is written the margins of the suggested gains are computed on the identified inertia
(tuning.control.margins); gains with less than 45 degrees of phase or 6 dB of gain margin are refused, naming the
highest level that keeps them, unless forced.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.gain_units import from_canonical, to_canonical
from servotool.model.profile import Entry, Profile
from servotool.tuning.control.gains import GainSuggestion, LoopGains, RigidityScale, rigidity_scale, suggest_gains
from servotool.tuning.control.margins import MIN_GAIN_DB, MIN_PHASE_DEG, Margins, margins
from servotool.tuning.errors import IdentificationFailed, MarginRefused
from servotool.tuning.preflight import FEATURE

GAIN_ROLES = {
    "speed_loop_gain": "speed_loop_gain_hz",
    "speed_loop_integral": "speed_integral_ms",
    "position_loop_gain": "position_loop_gain_per_s",
    "torque_filter": "torque_filter_ms",
}


@dataclass(frozen=True)
class GainChange:
    role: str
    entry: Entry
    old: float
    new: float
    raw: int
    old_raw: int = 0


def configured_inertia(profile: Profile, j_total_kgm2: float, configured_kgm2: float | None = None) -> float:
    """The inertia the drive's speed gain is computed with: the one its ratio parameter holds (configured_kgm2,
    where that is not the load's: `tune gains --load-ratio` writes no ratio), else the load's once the ratio is
    written, or the rotor's alone where the drive has no ratio parameter (SDC: its speed gain is absolute, F3's
    levels are for "large-inertia loads" below the factory level)."""
    motor = profile.motor
    assert motor is not None
    if profile.role("inertia_ratio") is None:
        return motor.rotor_inertia_kgcm2 * 1e-4
    return configured_kgm2 if configured_kgm2 is not None else j_total_kgm2


def loop_margins(
    profile: Profile,
    loop: LoopGains,
    j_total_kgm2: float,
    viscous: float = 0.0,
    configured_kgm2: float | None = None,
) -> Margins:
    return margins(loop, j_total_kgm2, configured_inertia(profile, j_total_kgm2, configured_kgm2), viscous)


def safe_level(
    profile: Profile,
    scale: RigidityScale,
    j_total_kgm2: float,
    upto: int | None = None,
    configured_kgm2: float | None = None,
) -> int | None:
    """The highest level (up to `upto`) whose gains keep the minimum margins; None when none does."""
    top = scale.highest if upto is None else upto
    for level in range(top, scale.lowest - 1, -1):
        loop = scale.factory.scaled(scale.factor(level))
        if loop_margins(profile, loop, j_total_kgm2, configured_kgm2=configured_kgm2).ok():
            return level
    return None


def current_level(drive: Drive, scale: RigidityScale) -> int:
    """The drive's rigidity level now (its factory level where it has no parameter for it)."""
    if scale.parameter is None:
        return scale.factory_level
    level = int(raw_to_eng(scale.parameter, drive.read_entries([scale.parameter])[0].raw))
    return max(scale.lowest, min(scale.highest, level))


def gain_changes(
    drive: Drive,
    load_ratio: float,
    *,
    rigidity: int | None,
    bandwidth_hz: float | None,
    force: bool = False,
    configured_kgm2: float | None = None,
) -> tuple[GainSuggestion, list[GainChange], Margins]:
    """Gains for the identified inertia at the drive's own level (its current one when neither is given), mapped
    onto the profile's gain roles (and its rigidity parameter), with their margins (configured_kgm2: the inertia
    the drive's ratio parameter holds, where it is not the load's); MarginRefused unless forced."""
    p = drive.profile
    motor = p.motor
    assert motor is not None
    scale = rigidity_scale(p)
    if rigidity is None and bandwidth_hz is None:
        rigidity = current_level(drive, scale)
    try:
        sugg = suggest_gains(
            rotor_inertia_kgcm2=motor.rotor_inertia_kgcm2,
            scale=scale,
            load_ratio=max(0.0, load_ratio),
            rigidity=rigidity,
            bandwidth_hz=bandwidth_hz,
        )
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    found = loop_margins(p, sugg.loop, sugg.j_total_kgm2, configured_kgm2=configured_kgm2)
    if not found.ok() and not force:
        what = f"rigidity {rigidity}" if rigidity is not None else f"{bandwidth_hz:g} Hz"
        safe = safe_level(p, scale, sugg.j_total_kgm2, rigidity, configured_kgm2)
        hint = (
            f"the highest level that keeps them is {safe} (--rigidity {safe})" if safe is not None else "no level does"
        )
        raise MarginRefused(
            f"{what} leaves {found.describe()} on the identified inertia, under the "
            f"{MIN_PHASE_DEG:g}° and {MIN_GAIN_DB:g} dB minimum: {hint}; --force writes it anyway"
        )
    entries = [(role, p.role(role)) for role in GAIN_ROLES]
    present = [(role, e) for role, e in entries if e is not None]
    if scale.parameter is not None and rigidity is not None:
        present.append(("rigidity", scale.parameter))
    current = drive.read_entries([e for _, e in present])
    changes = []
    for (role, e), reading in zip(present, current, strict=True):
        value = float(rigidity) if role == "rigidity" else from_canonical(role, e, getattr(sugg, GAIN_ROLES[role]))
        raw = eng_to_raw(e, value)
        changes.append(
            GainChange(role, e, float(raw_to_eng(e, reading.raw)), float(raw_to_eng(e, raw)), raw, reading.raw)
        )
    return sugg, changes, found


def drive_loop(drive: Drive) -> LoopGains:
    """The gains the drive runs now, in canonical units (the factory's where a role is not mapped)."""
    p = drive.profile
    factory = rigidity_scale(p).factory
    fallback = {
        "speed_loop_gain": factory.speed_hz,
        "speed_loop_integral": factory.integral_ms,
        "position_loop_gain": factory.position_per_s,
        "torque_filter": factory.filter_ms,
    }
    present = [(role, e) for role in GAIN_ROLES if (e := p.role(role)) is not None]
    values = dict(fallback)
    for (role, e), reading in zip(present, drive.read_entries([e for _, e in present]), strict=True):
        values[role] = to_canonical(role, e, float(raw_to_eng(e, reading.raw)))
    return LoopGains(
        values["speed_loop_gain"], values["speed_loop_integral"], values["position_loop_gain"], values["torque_filter"]
    )


NEAREST_SHARE = 0.02
"""A ratio just outside the parameter's range is written as the nearest end when that is within this share of
J_total or the estimate's 3 sigma: SD25's Po013 starts at 0.01, and a bare motor (0.00 or a little below) must not
be refused for it."""


def ratio_raw(drive: Drive, load_ratio: float, std: float = 0.0) -> tuple[Entry, int]:
    p, entry = drive.profile, drive.profile.need_role("inertia_ratio", FEATURE)
    raw = eng_to_raw(entry, p.param_from_load_ratio(max(0.0, load_ratio)), clamp=False)
    nearest = max(entry.min, min(entry.max, raw))
    off = abs(p.load_ratio_from_param(nearest * entry.scale) - load_ratio)
    if off <= max(NEAREST_SHARE * (1.0 + max(0.0, load_ratio)), 3.0 * std):
        raw = nearest
    if not entry.min <= raw <= entry.max:
        raise IdentificationFailed(f"identified ratio {load_ratio:.2f} does not fit {entry.code}'s range")
    return entry, raw
