"""A position hold that stays stable while the load is still unknown: identification on a position-mode route.

IS620P's segment route (issue 15) ends every move in the drive's position hold. The drive computes its speed-loop
gain from the *configured* inertia ratio (H08-00 is a bandwidth in Hz, which it only is for the inertia H08-15
describes), while the position gain H08-02 and the speed integral H08-01 are absolute. With a load far above the
configured ratio the speed loop is slow, the position loop and the integral are not, and the hold swings with
growing amplitude: at the factory gains (25 Hz, 31.83 ms, 40.0) and ratio 1.00 the margins model (tuning.margins)
leaves the position loop no phase margin beyond a load of about 17; issue 16 saw 37 and 49 run into the travel
guard. The CANopen manual prints the gains and H08-15 (0.00~120.00, default 1.00; L3260-3272) but no formula for
how the ratio enters the speed loop, and its commissioning runs velocity mode at low speed before gains are adjusted
(section 4.4 steps 8-9, L1447-1448); the drive's own offline identification (H09-05..H09-09) is a speed profile.

So, on a route that holds position, the identification
  - before the pilot: lengthens the speed integral and then lowers the position gain as far as the margins need
    for any load up to the ratio parameter's maximum at the configured ratio (never raising either);
  - after the pilot: writes the pilot's rough estimate as the inertia ratio (the speed loop then has the bandwidth
    its gain says) and takes the integral and position gain back towards the drive's own as far as the margins
    allow for a load within PILOT_SPREAD of that estimate.
Each change is a parameter written through ops.params.write_one, its original value recorded in the motion's
settings to put back (motion.jogger.Jogger.leave_and_restore), so the drive ends as it was found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from servotool.drive import Drive
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.gain_units import from_canonical, to_canonical
from servotool.model.profile import Entry
from servotool.ops.params import write_one
from servotool.tuning.estimator import EstimatorSettings, InertiaEstimate
from servotool.tuning.gains import LoopGains, rigidity_scale
from servotool.tuning.margins import margins

HOLD_MIN_PHASE_DEG = 35.0   # a temporary hold: well damped (a few % overshoot), not the 45° gains are written with
HOLD_MIN_GAIN_DB = 4.0
HEAVIEST_WITHOUT_PARAMETER = 100.0   # the heaviest load assumed where the profile maps no inertia-ratio parameter
PILOT_SPREAD = 2.0          # after the pilot: stable for a true J_total within [J/2, 2 J] of its estimate
PILOT_MAX_REL_STD = 0.25    # a pilot estimate with a larger relative uncertainty of J_total is not used
# The pilot's fit may use smaller speed changes than the final one: a sluggish loop (the ratio far below the load)
# hardly follows the pilot's ramps, and a rough value (biased low by about 1/excitation^2 before the fit's noise
# correction) is all the ratio needs.
PILOT_MIN_EXCITATION = 3.0
INTEGRAL_STEP = 1.5
POSITION_STEP = 1.5
MIN_POSITION_PER_S = 1.0    # never below: the hold must still pull the axis back where its move ended


@dataclass(frozen=True)
class HoldSetting:
    """The configured load ratio, speed integral (ms) and position gain (1/s) of the hold."""

    ratio: float
    integral_ms: float
    position_per_s: float


class StableHold:
    """Keeps the hold between identification moves stable: see the module docstring.

    `saved` is the motion's code -> raw of settings to put back; every entry written here is added to it first.
    Inactive (writes nothing) where the route does not end its moves in a position hold or the profile lacks the
    motor data or the gains."""

    def __init__(self, drive: Drive, route_kind: str, saved: dict[str, int]) -> None:
        self.drive, self.saved = drive, saved
        p = drive.profile
        self.entries: dict[str, Entry] = {role: e for role in ("inertia_ratio", "speed_loop_gain",
                                          "speed_loop_integral", "position_loop_gain", "torque_filter")
                                          if (e := p.role(role)) is not None}
        self.active = route_kind == "segment" and p.motor is not None and \
            "position_loop_gain" in self.entries and "speed_loop_integral" in self.entries
        self.loop: LoopGains | None = None
        self.original: HoldSetting | None = None
        self.setting: HoldSetting | None = None

    # ----- what the drive runs -------------------------------------------------------------------------------
    def _read(self) -> None:
        p = self.drive.profile
        factory = rigidity_scale(p).factory
        values = {"speed_loop_gain": factory.speed_hz, "speed_loop_integral": factory.integral_ms,
                  "position_loop_gain": factory.position_per_s, "torque_filter": factory.filter_ms}
        entries = list(self.entries.items())
        ratio = 0.0
        for (role, e), r in zip(entries, self.drive.read_entries([e for _, e in entries]), strict=True):
            eng = float(raw_to_eng(e, r.raw))
            if role == "inertia_ratio":
                ratio = max(0.0, p.load_ratio_from_param(eng))
            else:
                values[role] = to_canonical(role, e, eng)
        self.loop = LoopGains(values["speed_loop_gain"], values["speed_loop_integral"],
                              values["position_loop_gain"], values["torque_filter"])
        self.original = HoldSetting(ratio, self.loop.integral_ms, self.loop.position_per_s)
        self.setting = self.original

    def heaviest(self) -> float:
        """The heaviest load ratio the hold must stand before the load is known: what the ratio parameter holds."""
        e = self.entries.get("inertia_ratio")
        if e is None:
            return HEAVIEST_WITHOUT_PARAMETER
        return self.drive.profile.load_ratio_from_param(float(raw_to_eng(e, e.max)))

    # ----- the two steps -------------------------------------------------------------------------------------
    def before_pilot(self) -> HoldSetting | None:
        """Soften the hold for any load up to heaviest() at the configured ratio; the setting (None: inactive)."""
        if not self.active:
            return None
        self._read()
        assert self.original is not None
        chosen = self.safe(self.original, 0.0, self.heaviest(), self.original)
        self._apply(chosen)
        return chosen

    def after_pilot(self, estimate: InertiaEstimate | None) -> HoldSetting | None:
        """The pilot's rough estimate as the configured ratio, the hold as near the drive's own as is safe for a load
        within PILOT_SPREAD of it; nothing changes when the estimate is not usable."""
        if not self.active or self.original is None or not usable(estimate):
            return None
        assert estimate is not None
        ratio_e = self.entries.get("inertia_ratio")
        # Only ever raised: the pilot measured how far the loop lags its ramps, which a slower loop would exceed.
        ratio = max(self.original.ratio, self._fit_ratio(estimate.load_ratio)) if ratio_e is not None else \
            self.original.ratio
        j = 1.0 + estimate.load_ratio
        lo, hi = max(0.0, j / PILOT_SPREAD - 1.0), j * PILOT_SPREAD - 1.0
        start = HoldSetting(ratio, self.original.integral_ms, self.original.position_per_s)
        chosen = self.safe(start, lo, hi, self.setting or self.original)
        self._apply(chosen)
        return chosen

    def _fit_ratio(self, load_ratio: float) -> float:
        """The load ratio as the parameter holds it (rounded to its resolution, within its range)."""
        p, e = self.drive.profile, self.entries["inertia_ratio"]
        raw = eng_to_raw(e, p.param_from_load_ratio(max(0.0, load_ratio)), clamp=True)
        return max(0.0, p.load_ratio_from_param(float(raw_to_eng(e, raw))))

    # ----- the margins ---------------------------------------------------------------------------------------
    def stable(self, setting: HoldSetting, lo: float, hi: float) -> bool:
        """Whether the hold keeps its minimum margins for every load ratio in [lo, hi] (checked at both ends and
        in between on a log grid of J_total)."""
        assert self.loop is not None and self.drive.profile.motor is not None
        jm = self.drive.profile.motor.rotor_inertia_kgcm2 * 1e-4
        loop = LoopGains(self.loop.speed_hz, setting.integral_ms, setting.position_per_s, self.loop.filter_ms)
        j_conf = jm * (1.0 + setting.ratio)
        steps = max(1, math.ceil(math.log((1.0 + hi) / (1.0 + lo)) / math.log(2.0)))
        for k in range(steps + 1):
            j = jm * (1.0 + lo) * ((1.0 + hi) / (1.0 + lo)) ** (k / steps)
            if not margins(loop, j, j_conf).ok(HOLD_MIN_PHASE_DEG, HOLD_MIN_GAIN_DB):
                return False
        return True

    def safe(self, start: HoldSetting, lo: float, hi: float, fallback: HoldSetting) -> HoldSetting:
        """The setting nearest `start` that is stable over [lo, hi]: the integral lengthened first (up to its
        parameter's maximum), then the position gain lowered; `fallback` when none is (a light-load limit no
        softer hold can help, such as a ratio configured far above the load)."""
        integral_max = self._limit("speed_loop_integral", high=True)
        position_min = max(MIN_POSITION_PER_S, self._limit("position_loop_gain", high=False))
        setting = start
        while not self.stable(setting, lo, hi):
            if setting.integral_ms < integral_max:
                setting = HoldSetting(setting.ratio, min(integral_max, setting.integral_ms * INTEGRAL_STEP),
                                      setting.position_per_s)
            elif setting.position_per_s > position_min:
                setting = HoldSetting(setting.ratio, setting.integral_ms,
                                      max(position_min, setting.position_per_s / POSITION_STEP))
            else:
                return fallback if self.stable(fallback, lo, hi) else setting
        return setting

    def _limit(self, role: str, high: bool) -> float:
        e = self.entries[role]
        return to_canonical(role, e, float(raw_to_eng(e, e.max if high else e.min)))

    # ----- writing -------------------------------------------------------------------------------------------
    def _apply(self, setting: HoldSetting) -> None:
        """Write what differs from the drive's present setting, each original recorded to be put back."""
        assert self.setting is not None
        p = self.drive.profile
        wanted: list[tuple[str, float]] = [("speed_loop_integral", setting.integral_ms),
                                           ("position_loop_gain", setting.position_per_s)]
        if "inertia_ratio" in self.entries:
            wanted.insert(0, ("inertia_ratio", p.param_from_load_ratio(setting.ratio)))
        entries = [self.entries[role] for role, _ in wanted]
        for (role, value), e, r in zip(wanted, entries, self.drive.read_entries(entries), strict=True):
            eng = value if role == "inertia_ratio" else from_canonical(role, e, value)
            raw = eng_to_raw(e, eng, clamp=True)
            if raw != r.raw:
                self.saved.setdefault(e.code, r.raw)
                write_one(self.drive, e, raw)
        self.setting = setting


def pilot_settings(settings: EstimatorSettings) -> EstimatorSettings:
    """The estimator's settings for the pilot's rough estimate."""
    return replace(settings, min_excitation=min(settings.min_excitation, PILOT_MIN_EXCITATION))


def usable(estimate: InertiaEstimate | None) -> bool:
    """A pilot estimate precise enough to configure the ratio with (it need not pass the final fit's checks)."""
    return estimate is not None and math.isfinite(estimate.load_ratio) and math.isfinite(estimate.j_std_kgm2) \
        and estimate.j_total_kgm2 > 0 and estimate.j_std_kgm2 <= PILOT_MAX_REL_STD * estimate.j_total_kgm2
