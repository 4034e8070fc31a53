"""A position hold that stays stable while the load is still unknown, for motion on a route that holds position.

A segment route (IS620P's) ends every move in the drive's position hold. The drive computes its speed-loop gain
from the *configured* inertia ratio (H08-00 is a bandwidth in Hz only for the inertia H08-15 describes), while the
position gain H08-02 and the speed integral H08-01 are absolute: with a load far above the configured ratio the speed
loop is slow, the position loop and the integral are not, and the hold swings up (at the factory gains and ratio the
closed loop's poles, control.margins.least_damping, grow for any load above about 16). unverified: the CANopen manual
prints the gains and H08-15 (0.00~120.00, default 1.00; L3260-3272) but no formula for how the ratio enters the
speed loop; the usual Kp = 2 pi f J_motor (1 + ratio) is assumed, as in the simulator.

So, on a route that holds position, the identification
  - before the pilot: sets the ratio as high as an unloaded motor stays well damped (PILOT_LIGHT_DAMPING: a
    stiffer loop breaks a heavy load away against friction; a ratio configured far above a light load comes down),
    then lowers the position gain and, if that is not enough, lengthens the speed integral until the hold and the
    speed loop stay damped (HOLD_MIN_DAMPING) for any load up to the ratio parameter's maximum;
  - after the pilot: writes the pilot's rough estimate as the ratio (never below the pilot's: the pilot measured
    how far the loop lags its ramps, which a slower loop would exceed) and takes the position gain and integral
    back to the drive's own as far as a load within PILOT_SPREAD of that estimate allows.
A motion that must show or keep the drive's own speed loop while the load is unknown (the step check before
identification, a JOG: guarded_jogger) lowers only the position gain (soften_position).
Each change is a parameter written through ops.params.write_one (RAM only where the drive has a switch: the
identification runs inside ops.eeprom.ram_writes), its original value recorded in the motion's settings to put
back by the stop sequence (motion.stop), so the drive ends as it was found.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.gain_units import from_canonical, to_canonical
from servotool.model.profile import Entry
from servotool.motion.jogger import Jogger
from servotool.ops import journal
from servotool.ops.params import write_one
from servotool.tuning.control.gains import LoopGains, rigidity_scale
from servotool.tuning.control.margins import least_damping
from servotool.tuning.fit import EstimatorSettings, InertiaEstimate

# The least damping ratio the loops' poles may have: a swing shrinks to 40 % or less each cycle (exp(-2 pi z)).
HOLD_MIN_DAMPING = 0.15
PILOT_LIGHT_DAMPING = 0.3  # the pilot's raised ratio keeps an unloaded motor's loops at least this damped
PILOT_RATIO_STEP = 1.25
HEAVIEST_WITHOUT_PARAMETER = 100.0  # the heaviest load assumed where the profile maps no inertia-ratio parameter
PILOT_SPREAD = 2.0  # after the pilot: stable for a true J_total within [J/2, 2 J] of its estimate
PILOT_MAX_REL_STD = 0.25  # a pilot estimate with a larger relative uncertainty of J_total is not used
# The pilot's fit may use fewer windows than the final one (two short moves), but not smaller speed changes: a fit on
# speed changes near the noise can give a far too high ratio with a 'usable' uncertainty, and that ratio written to
# the drive trips its overload alarm.
PILOT_MIN_WINDOWS = 4
INTEGRAL_STEP = 1.5
POSITION_STEP = 1.5
MIN_POSITION_PER_S = 1.0  # never below: the hold must still pull the axis back where its move ended


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
        self.entries: dict[str, Entry] = {
            role: e
            for role in (
                "inertia_ratio",
                "speed_loop_gain",
                "speed_loop_integral",
                "position_loop_gain",
                "torque_filter",
            )
            if (e := p.role(role)) is not None
        }
        self.active = (
            route_kind == "segment"
            and p.motor is not None
            and "position_loop_gain" in self.entries
            and "speed_loop_integral" in self.entries
        )
        self.loop: LoopGains | None = None
        self.raws: dict[str, int] = {}  # what the drive holds now (read once, then as written): requests count
        self.original: HoldSetting | None = None
        self.setting: HoldSetting | None = None

    # ----- what the drive runs -------------------------------------------------------------------------------
    def _read(self) -> None:
        p = self.drive.profile
        factory = rigidity_scale(p).factory
        values = {
            "speed_loop_gain": factory.speed_hz,
            "speed_loop_integral": factory.integral_ms,
            "position_loop_gain": factory.position_per_s,
            "torque_filter": factory.filter_ms,
        }
        entries = list(self.entries.items())
        ratio = 0.0
        for (role, e), r in zip(entries, self.drive.read_entries([e for _, e in entries]), strict=True):
            self.raws[e.code] = r.raw
            eng = float(raw_to_eng(e, r.raw))
            if role == "inertia_ratio":
                ratio = max(0.0, p.load_ratio_from_param(eng))
            else:
                values[role] = to_canonical(role, e, eng)
        self.loop = LoopGains(
            values["speed_loop_gain"],
            values["speed_loop_integral"],
            values["position_loop_gain"],
            values["torque_filter"],
        )
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
        start = HoldSetting(self._pilot_ratio(), self.original.integral_ms, self.original.position_per_s)
        chosen = self.safe(start, 0.0, self.heaviest(), self.original)
        self._apply(chosen)
        return chosen

    def soften_position(self) -> HoldSetting | None:
        """Only the position gain lowered, as far as the heaviest load needs (best effort: the ratio and integral
        stay as configured), for a motion that must show the drive's own speed loop (the step check before
        identification); the setting (None: inactive)."""
        if not self.active:
            return None
        self._read()
        assert self.original is not None
        chosen = self.safe(self.original, 0.0, self.heaviest(), self.original, integral=False)
        self._apply(chosen)
        return chosen

    def _pilot_ratio(self) -> float:
        """The highest ratio that keeps an unloaded motor's loops damped by PILOT_LIGHT_DAMPING: raised from the
        configured one (a stiffer speed loop breaks a heavy load away against friction in the pilot), or lowered
        where the configured one is far above a light load (a loop that stiff drives a bare motor into the overload
        alarm)."""
        assert self.original is not None
        e = self.entries.get("inertia_ratio")
        if e is None:
            return self.original.ratio
        top = self.drive.profile.load_ratio_from_param(float(raw_to_eng(e, e.max)))

        def damped(ratio: float) -> bool:
            setting = HoldSetting(ratio, self.original.integral_ms, self.original.position_per_s)
            return self.damping(setting, 0.0) >= PILOT_LIGHT_DAMPING

        ratio = self.original.ratio
        while ratio > 0.0 and not damped(ratio):
            ratio = self._fit_ratio((1.0 + ratio) / PILOT_RATIO_STEP - 1.0)
        while True:
            bigger = self._fit_ratio(min(top, (1.0 + ratio) * PILOT_RATIO_STEP - 1.0))
            if bigger <= ratio or not damped(bigger):
                return ratio
            ratio = bigger

    def after_pilot(self, estimate: InertiaEstimate | None) -> HoldSetting | None:
        """The pilot's rough estimate as the configured ratio, the hold as near the drive's own as is safe for a load
        within PILOT_SPREAD of it; nothing changes when the estimate is not usable."""
        if not self.active or self.original is None or not usable(estimate):
            return None
        assert estimate is not None
        ratio_e = self.entries.get("inertia_ratio")
        # Only ever raised: the pilot measured how far the loop lags its ramps, which a slower loop would exceed.
        pilot_ratio = (self.setting or self.original).ratio
        ratio = max(pilot_ratio, self._fit_ratio(estimate.load_ratio)) if ratio_e is not None else pilot_ratio
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
    def damping(self, setting: HoldSetting, load_ratio: float) -> float:
        """The least damping of the hold and the speed loop on this load with this setting."""
        assert self.loop is not None and self.drive.profile.motor is not None
        jm = self.drive.profile.motor.rotor_inertia_kgcm2 * 1e-4
        loop = LoopGains(self.loop.speed_hz, setting.integral_ms, setting.position_per_s, self.loop.filter_ms)
        j, j_conf = jm * (1.0 + load_ratio), jm * (1.0 + setting.ratio)
        return min(least_damping(loop, j, j_conf), least_damping(loop, j, j_conf, position=False))

    def stable(self, setting: HoldSetting, lo: float, hi: float) -> bool:
        """Whether the hold and the speed loop keep HOLD_MIN_DAMPING for every load ratio in [lo, hi] (checked at
        both ends and in between on a log grid of J_total)."""
        steps = max(1, math.ceil(math.log((1.0 + hi) / (1.0 + lo)) / math.log(2.0)))
        return all(
            self.damping(setting, (1.0 + lo) * ((1.0 + hi) / (1.0 + lo)) ** (k / steps) - 1.0) >= HOLD_MIN_DAMPING
            for k in range(steps + 1)
        )

    def safe(
        self, start: HoldSetting, lo: float, hi: float, fallback: HoldSetting, integral: bool = True
    ) -> HoldSetting:
        """The setting nearest `start` that is stable over [lo, hi]: the position gain lowered first (down to
        MIN_POSITION_PER_S), then the integral lengthened (up to its parameter's maximum: a long integral is slow to
        break the axis away against friction; integral=False leaves it); `fallback` when none is and the fallback is
        stable (a light-load limit no softer hold can help, such as a ratio configured far above the load), else the
        softest setting tried."""
        integral_max = self._limit("speed_loop_integral", high=True)
        position_min = max(MIN_POSITION_PER_S, self._limit("position_loop_gain", high=False))
        setting = start
        while not self.stable(setting, lo, hi):
            if setting.position_per_s > position_min:
                setting = HoldSetting(
                    setting.ratio, setting.integral_ms, max(position_min, setting.position_per_s / POSITION_STEP)
                )
            elif integral and setting.integral_ms < integral_max:
                setting = HoldSetting(
                    setting.ratio, min(integral_max, setting.integral_ms * INTEGRAL_STEP), setting.position_per_s
                )
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
        wanted: list[tuple[str, float]] = [
            ("speed_loop_integral", setting.integral_ms),
            ("position_loop_gain", setting.position_per_s),
        ]
        if "inertia_ratio" in self.entries:
            wanted.insert(0, ("inertia_ratio", p.param_from_load_ratio(setting.ratio)))
        for role, value in wanted:
            e = self.entries[role]
            eng = value if role == "inertia_ratio" else from_canonical(role, e, value)
            raw = eng_to_raw(e, eng, clamp=True)
            if raw != self.raws[e.code]:
                if e.code not in self.saved:
                    self.saved[e.code] = self.raws[e.code]
                    journal.note_settings(self.drive, self.saved)
                write_one(self.drive, e, raw, self.raws[e.code])
                self.raws[e.code] = raw
        self.setting = setting


def guarded_jogger(drive: Drive, clock: Clock | None = None) -> Jogger:
    """The Jogger every JOG of an unknown load runs on (`servotool jog`, a plan's jog step): where its route holds
    position, each JOG lowers the position gain as the step check does (StableHold.soften_position), since a hold
    tuned for a lighter load swings up after the stop; the gain goes back with the JOG's other settings."""
    jogger = Jogger(drive, clock=clock)
    jogger.prepare = lambda saved: StableHold(drive, jogger.route.kind, saved).soften_position()
    return jogger


def pilot_settings(settings: EstimatorSettings) -> EstimatorSettings:
    """The estimator's settings for the pilot's rough estimate."""
    return replace(settings, min_windows=min(settings.min_windows, PILOT_MIN_WINDOWS))


def usable(estimate: InertiaEstimate | None) -> bool:
    """A pilot estimate precise enough to configure the ratio with (it need not pass the final fit's checks)."""
    return (
        estimate is not None
        and math.isfinite(estimate.load_ratio)
        and math.isfinite(estimate.j_std_kgm2)
        and estimate.j_total_kgm2 > 0
        and estimate.j_std_kgm2 <= PILOT_MAX_REL_STD * estimate.j_total_kgm2
    )
