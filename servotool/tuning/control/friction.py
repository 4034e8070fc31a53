"""Friction found by the identification, in the drive's units, and the drive's friction-compensation entries for it.

The estimator gives Coulomb friction (N*m), viscous friction (N*m per rad/s) and a constant load torque (N*m).
Drives state torque in % of rated: Coulomb and load torque as %, viscous as % at the rated speed. Where the profile
maps compensation entries (roles friction_comp_fwd/_rev, viscous_comp(_fwd/_rev), torque_offset: DSX7E Pn120-124,
SDC PN137-140) the values for them are suggested, never written: compensation changes how the loop behaves and is
the engineer's call.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.profile import Entry, Profile

RAD_S_PER_RPM = 2 * math.pi / 60


class FittedFriction(Protocol):
    """The friction and load torque a fit found (fit.InertiaEstimate has them), in SI units."""

    @property
    def coulomb_nm(self) -> float: ...
    @property
    def viscous_nm_per_rad_s(self) -> float: ...
    @property
    def load_torque_nm(self) -> float: ...


@dataclass(frozen=True)
class FrictionSetting:
    entry: Entry
    value: float  # in the entry's unit, rounded to its scale
    what: str


@dataclass(frozen=True)
class FrictionReport:
    coulomb_pct: float  # % of rated torque
    viscous_pct_at_rated: float  # % of rated torque at the rated speed
    load_pct: float  # constant load torque, % of rated (positive opposes forward motion)
    settings: list[FrictionSetting]

    def describe(self) -> str:
        return (
            f"friction {self.coulomb_pct:.1f} % of rated torque (Coulomb), viscous {self.viscous_pct_at_rated:.1f}"
            f" % at rated speed, load torque {self.load_pct:+.1f} %"
        )


def friction_report(profile: Profile, est: FittedFriction) -> FrictionReport | None:
    """The estimate's friction in drive units with the profile's compensation entries; None without a motor."""
    motor = profile.motor
    if motor is None or not all(math.isfinite(x) for x in (est.coulomb_nm, est.viscous_nm_per_rad_s)):
        return None
    rated = motor.rated_torque_nm
    coulomb = est.coulomb_nm / rated * 100
    viscous = est.viscous_nm_per_rad_s * motor.rated_speed_rpm * RAD_S_PER_RPM / rated * 100
    load = est.load_torque_nm / rated * 100 if math.isfinite(est.load_torque_nm) else 0.0
    wanted = {
        "friction_comp_fwd": (coulomb, "Coulomb friction, forward"),
        "friction_comp_rev": (coulomb, "Coulomb friction, reverse"),
        "viscous_comp_fwd": (viscous, "viscous friction at rated speed, forward"),
        "viscous_comp_rev": (viscous, "viscous friction at rated speed, reverse"),
        "viscous_comp": (viscous, "viscous friction at rated speed, both directions"),
        "torque_offset": (load, "constant load torque (gravity)"),
    }
    settings = []
    for role, (value, what) in wanted.items():
        entry = profile.role(role)
        if entry is None or entry.unit != "%":
            continue
        raw = eng_to_raw(entry, value)  # clamped to the entry's range
        settings.append(FrictionSetting(entry, float(raw_to_eng(entry, raw)), what))
    return FrictionReport(coulomb, viscous, load, settings)
