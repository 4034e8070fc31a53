"""Physics and servo control loops behind the simulated drive (no Modbus here).

Rigid motor + load: J = Jm * (1 + load_ratio), with Coulomb friction (and stiction at rest), viscous friction and a
constant load torque (gravity axis). Sign convention: J dw/dt = T - Tc*sign(w) - B*w - Tg. Mechanics outside that
model (a compliant coupling, backlash, an arm's position-dependent gravity, cogging) are in sim.mechanics, off by
default.
An optional holding brake adds BRAKE_HOLD_X_RATED x rated torque of friction while it is closed: the drive closes it
after servo off once the motor is below BRAKE_ENGAGE_RPM or BRAKE_DELAY_S after servo off (IS620P H02-11/H02-12
defaults), and opens it at servo on. Without a brake a gravity load falls with servo off, limited only by friction.
Position mode is a servo-on drive in its control mode: while a (ramped) host speed profile moves, the speed loop
follows it under speed control; once the profile is at rest the position loop (P) holds the position where it
stopped, and a following error beyond the drive's limit (FOLLOWING_LIMIT_REV when the drive has no parameter for it)
latches the following-error alarm instead of letting a load drift the axis away.
The drive's speed PI computes its gain from the *configured* inertia ratio, as real drives do, so a wrong ratio shows
as a sluggish, overshooting or oscillating loop. The loop runs at a 125 us control period with a one-sample delay,
a speed-feedback filter and the torque-command filter from the drive's parameters.

Time is integrated only when asked (`advance_to`), so an idle simulator costs nothing.
"""

from __future__ import annotations

import math
import random
from dataclasses import asdict, dataclass, field

from servotool.model.profile import Motor as MotorData
from servotool.sim.loop_functions import FrictionFeedForward, GainSelector, GainSwitch, Notch, NotchSetting
from servotool.sim.mechanics import Friction, Mechanics, MechanicsSettings, MotorState, friction_step

TS = 125e-6  # control period, s
SPEED_FILTER_S = 0.25e-3  # speed feedback low-pass
CURRENT_LOOP_S = 0.2e-3  # the current loop's lag between torque command and torque (about 800 Hz)
MAX_GAP_S = 20.0  # integrate at most this much at once; beyond it the state is carried over
RAD_S_PER_RPM = 2 * math.pi / 60
OVERLOAD_LIMIT = 8.0  # I^2t budget: 300 % torque trips after 1 s, 200 % after 2.7 s
FOLLOWING_LIMIT_REV = 3.0  # simulator default following-error limit (IS620P H0A-10's default is 3 rev of its encoder)
BRAKE_HOLD_X_RATED = 2.5  # brake holding torque: above the largest configurable load torque, so a brake always holds
BRAKE_ENGAGE_RPM = 30.0  # brake closes after servo off below this speed (IS620P H02-11 default) ...
BRAKE_DELAY_S = 0.5  # ... or this long after servo off at speed (IS620P H02-12 default)
ESTOP_MAX_S = 0.5  # an alarm stop at the torque limit lasts at most this long, then the motor is switched off
OVERSPEED_X_MAX = 1.2  # the overspeed alarm: this many times the motor's top speed (IS620P H0A-08 = 0: automatic)
LOCKED_SPEED_SHARE = 0.1  # a locked rotor: under this share of the commanded speed ...
LOCKED_TORQUE_SHARE = 0.9  # ... with the torque at this share of its limit or more
VIBRATION_LOWPASS_S = 1.0 / (2 * math.pi * 20.0)  # the torque command's vibration: what lies above 20 Hz ...
VIBRATION_AVERAGE_S = 0.05  # ... as an RMS over about this long (the simulator's adaptive notch watches it)
# The plant's dynamic state, as persisted between processes serving one simulated drive (the drive stays powered).
STATE_FIELDS = (
    "time",
    "w",
    "theta",
    "mode",
    "alarm",
    "_w_meas",
    "_theta_prev_counts",
    "_integral",
    "_t_cmd",
    "_t_filtered",
    "_t_applied",
    "_t_delayed",
    "_ref",
    "_loop_ref",
    "_target",
    "_torque_target",
    "_pos_ref",
    "_heat",
    "_load",
    "_off_s",
    "_estop_s",
    "_defl",
    "_defl_rate",
    "_locked_s",
    "_saturated_s",
)


@dataclass(frozen=True)
class PlantSettings:
    """The machine's true properties (SI units)."""

    load_ratio: float = 0.0
    coulomb_nm: float = 0.0
    viscous_nm_per_rad_s: float = 0.0
    load_torque_nm: float = 0.0
    noise: float = 0.0  # speed std = noise * 1000 rpm, torque std = noise * 100 % of rated
    seed: int = 1
    brake_nm: float = 0.0  # holding brake torque; 0 = no brake
    mechanics: MechanicsSettings = field(default_factory=MechanicsSettings)  # beyond the rigid load (off by default)


@dataclass(frozen=True)
class DriveGains:
    """The drive's parameters that shape its loops (engineering units)."""

    inertia_ratio_configured: float = 0.0
    speed_gain_hz: float = 40.0
    speed_integral_ms: float = 20.0
    position_gain_per_s: float = 40.0
    torque_filter_ms: float = 0.5
    torque_limit_pct: float = 300.0
    max_speed_rpm: float = 6000.0
    jog_accel_ms: float = 200.0  # time from 0 to rated speed
    following_limit_rev: float = FOLLOWING_LIMIT_REV
    notches: tuple[NotchSetting, ...] = ()  # torque-command notches (sim.loop_functions)
    friction_ff: FrictionFeedForward = field(default_factory=FrictionFeedForward)  # friction compensation
    gain_switch: GainSwitch = field(default_factory=GainSwitch)  # the second gain set and when it acts


@dataclass(frozen=True)
class Protections:
    """The drive's own protections that act on the motion (sim.protections reads them from its parameters).

    fence: (lowest, highest) position in revolutions of the plant's position and what the drive does beyond it:
    "stop" forces the speed in the direction of travel to zero at once (the reverse stays free), "alarm" latches
    the overtravel alarm. locked_rotor_s / saturation_s: how long a locked rotor (torque at its limit, the motor
    barely turning under a commanded speed) or a saturated speed regulator lasts before its alarm; None: off."""

    fence: tuple[float, float, str] | None = None
    locked_rotor_s: float | None = None
    saturation_s: float | None = None


class Plant:
    """Motor, load and the drive's control loops, integrated on demand."""

    def __init__(self, motor: MotorData, settings: PlantSettings, gains: DriveGains, start_time: float = 0.0) -> None:
        self.motor = motor
        self.time = start_time
        self.w = 0.0  # rad/s
        self.theta = 0.0  # rad
        self.mode = "off"  # off | speed | torque | position | estop
        self.alarm: str | None = None
        self._w_meas = 0.0
        self._theta_prev_counts = 0
        self._integral = 0.0
        self._t_cmd = 0.0  # torque command before the filter, N*m
        self._t_filtered = 0.0  # after the torque-command filter
        self._t_applied = 0.0  # produced by the current loop
        self._t_delayed = 0.0
        self._ref = 0.0  # ramped speed reference (the speed profile), rad/s
        self._loop_ref = 0.0  # the speed loop's reference (position mode: profile + position loop output)
        self._target = 0.0  # speed command, rad/s
        self._torque_target = 0.0  # N*m (torque mode)
        self._pos_ref = 0.0
        self._heat = 0.0
        self._load = 0.0
        self._off_s = math.inf  # time since servo off (brake timing)
        self._estop_s = 0.0  # time in the alarm stop
        self._defl = 0.0  # a compliant coupling's deflection (motor minus load angle), rad; 0 when rigid
        self._defl_rate = 0.0  # and its rate, rad/s
        self._locked_s = 0.0  # how long the rotor has been locked under a speed command
        self._saturated_s = 0.0  # how long the speed regulator's output has sat at the torque limit
        self._t_slow = 0.0  # the torque command low-passed (VIBRATION_LOWPASS_S) ...
        self._vibration = 0.0  # ... and the mean square of what lies above it, N*m^2
        self.watch_vibration = False  # measured only while something watches it (an adaptive notch that adapts)
        self.protections = Protections()
        self.set_settings(settings)
        self.set_gains(gains)

    # ----- configuration -------------------------------------------------------------------------------------
    def set_settings(self, settings: PlantSettings) -> None:
        self.settings = settings
        self.j = self.motor.jm * (1.0 + settings.load_ratio)
        self.mech = Mechanics(self.motor.jm, settings.load_ratio, settings.mechanics)
        if not self.mech.coupled:
            self._defl = self._defl_rate = 0.0
        self._rng = random.Random(settings.seed)

    def set_gains(self, gains: DriveGains) -> None:
        old = getattr(self, "gains", None)
        self.gains = gains
        if old is None or old.notches != gains.notches:  # a filter keeps its state while its setting stays
            self._notches = [Notch(n, TS) for n in gains.notches if n.active(TS)]
        self._ff = gains.friction_ff if gains.friction_ff.any else None
        j_conf = self.motor.jm * (1.0 + gains.inertia_ratio_configured)
        self._kp = 2 * math.pi * gains.speed_gain_hz * j_conf
        self._ti = max(gains.speed_integral_ms, 0.1) / 1000.0
        self._kp_pos = gains.position_gain_per_s
        sw = gains.gain_switch
        if old is None or old.gain_switch != sw:  # the selector keeps its state while its setting stays
            self._gain_select = GainSelector(sw) if sw.any else None
        # (speed loop P, integral time, position gain) of gain set 1 and 2
        self._gain_sets = (
            (self._kp, self._ti, self._kp_pos),
            (2 * math.pi * sw.speed_gain_hz * j_conf, max(sw.speed_integral_ms, 0.1) / 1000.0, sw.position_gain_per_s),
        )
        self._tf = max(gains.torque_filter_ms, 0.0) / 1000.0
        self._t_lim = gains.torque_limit_pct / 100.0 * self.motor.rated_torque_nm
        self._ramp = self.motor.rated_speed_rpm * RAD_S_PER_RPM / max(gains.jog_accel_ms / 1000.0, 1e-3)

    @property
    def active_gain_set(self) -> int:
        """The gain set acting now (1 or 2: gain switching)."""
        return self._gain_select.active if self._gain_select is not None else 1

    def set_protections(self, protections: Protections) -> None:
        self.protections = protections

    def set_mode(self, mode: str) -> None:
        if mode not in ("off", "speed", "torque", "position"):
            raise ValueError(f"unknown mode {mode}")
        if self.alarm is not None and mode != "off":
            return
        if mode != self.mode:
            self._integral = 0.0
            self._ref = self.w if mode == "speed" else 0.0
            self._target = 0.0
            self._torque_target = 0.0
            self._pos_ref = self.theta
            self._locked_s = self._saturated_s = 0.0
            if mode == "off":
                self._off_s = 0.0
        self.mode = mode

    def set_speed_command(self, rpm: float) -> None:
        limit = min(self.gains.max_speed_rpm, self.motor.max_speed_rpm)
        self._target = max(-limit, min(limit, rpm)) * RAD_S_PER_RPM

    def set_torque_command(self, pct: float) -> None:
        self._torque_target = pct / 100.0 * self.motor.rated_torque_nm

    def raise_alarm(self, name: str) -> None:
        """Latch an alarm; the drive stops the motor at its torque limit, then switches off."""
        if self.alarm is None:
            self.alarm = name
            if self.mode != "off":
                self.mode = "estop"
                self._ref = self.w
                self._target = 0.0
                self._estop_s = 0.0

    def clear_alarms(self) -> bool:
        """Clear only when the cause is gone (overload must have cooled down, motor not over speed)."""
        if self.alarm is None:
            return True
        if self.alarm == "overload" and self._heat > 0.5 * OVERLOAD_LIMIT:
            return False
        if self.alarm == "overspeed" and abs(self.w) > self.motor.max_speed_rpm * RAD_S_PER_RPM:
            return False
        self.alarm = None
        return True

    # ----- readouts ------------------------------------------------------------------------------------------
    @property
    def servo_on(self) -> bool:
        return self.mode != "off"

    @property
    def true_speed_rpm(self) -> float:
        return self.w / RAD_S_PER_RPM

    @property
    def speed_rpm(self) -> float:
        return self._w_meas / RAD_S_PER_RPM + self._rng.gauss(0.0, self.settings.noise * 1000.0)

    @property
    def torque_pct(self) -> float:
        return self._t_applied / self.motor.rated_torque_nm * 100.0 + self._rng.gauss(0.0, self.settings.noise * 100)

    @property
    def true_torque_pct(self) -> float:
        return self._t_applied / self.motor.rated_torque_nm * 100.0

    @property
    def target_rpm(self) -> float:
        """The host's speed command (before the ramp)."""
        return self._target / RAD_S_PER_RPM

    @property
    def speed_command_rpm(self) -> float:
        if self.mode == "position":
            return self._loop_ref / RAD_S_PER_RPM
        return self._ref / RAD_S_PER_RPM if self.mode in ("speed", "estop") else 0.0

    @property
    def position_rev(self) -> float:
        return self.theta / (2 * math.pi)

    @property
    def position_counts(self) -> int:
        return math.floor(self.position_rev * self.motor.counts_per_rev)

    @property
    def _profile_moving(self) -> bool:
        return self._ref != 0.0 or self._target != 0.0

    @property
    def following_error_counts(self) -> int:
        if self.mode != "position" or self._profile_moving:  # no position loop under host motion
            return 0
        return round((self._pos_ref - self.theta) / (2 * math.pi) * self.motor.counts_per_rev)

    @property
    def vibration_pct(self) -> float:
        """The torque command's content above 20 Hz, RMS over about 50 ms, in % of rated torque."""
        return math.sqrt(max(self._vibration, 0.0)) / self.motor.rated_torque_nm * 100.0

    @property
    def load_rate_pct(self) -> float:
        return self._load

    @property
    def brake_closed(self) -> bool:
        """Whether the holding brake (if any) holds the shaft: servo off and slow enough or long enough."""
        return (
            self.settings.brake_nm > 0
            and self.mode == "off"
            and (self._off_s >= BRAKE_DELAY_S or abs(self.w) < BRAKE_ENGAGE_RPM * RAD_S_PER_RPM)
        )

    def _friction_nm(self) -> float:
        return self.settings.coulomb_nm + self._brake_nm()

    def _brake_nm(self) -> float:
        return self.settings.brake_nm if self.brake_closed else 0.0

    def _load_friction(self) -> Friction:
        s = self.settings
        return Friction(s.coulomb_nm, s.viscous_nm_per_rad_s, s.load_torque_nm)

    # ----- integration ---------------------------------------------------------------------------------------
    def advance_to(self, t: float) -> None:
        """Integrate from the last time to t with the fixed control period."""
        dt_total = t - self.time
        if dt_total <= 0:
            return
        if dt_total > MAX_GAP_S:
            self._cool(dt_total - MAX_GAP_S)
            self.time = t - MAX_GAP_S  # an idle gap: the state carries over, only the recent part is integrated
        if (
            self.mode == "off"
            and self.w == 0.0
            and self.mech.at_rest(self._motion_state(), self._brake_nm(), self._load_friction())
        ):
            self._cool(t - self.time)
            if self._gain_select is not None:  # at rest: below any switching speed all this while
                self._gain_select.step(0.0, t - self.time)
            self._off_s += t - self.time
            self.time = t  # at rest, nothing acting: nothing to integrate
            self._w_meas = 0.0
            self._t_applied = self._t_filtered = self._t_cmd = self._t_delayed = 0.0
            self._load = 0.0
            return
        steps = int((t - self.time) / TS + 1e-9)
        for _ in range(steps):
            self._step()
        self.time += steps * TS  # the remainder (< one period) is integrated by the next call

    def _cool(self, seconds: float) -> None:
        """The motor's I^2t heat over time not integrated step by step (no current: it falls by 1 per second)."""
        self._heat = max(0.0, self._heat - seconds)

    def _controller(self) -> float:
        """Torque command of this control period (before the filter)."""
        mode = self.mode
        if self._gain_select is not None:  # the condition is watched whatever the servo does
            chosen = self._gain_select.step(self._w_meas / RAD_S_PER_RPM, TS)
            self._kp, self._ti, self._kp_pos = self._gain_sets[chosen - 1]
        if mode == "off":
            self._integral = 0.0
            return 0.0
        if mode == "torque":
            return self._torque_target
        self._fence_stop()
        step = self._ramp * TS if mode in ("speed", "position") else math.inf
        self._ref += max(-step, min(step, self._target - self._ref))
        if mode == "position" and self._profile_moving:
            self._pos_ref = self.theta  # a host speed reference runs under speed control ...
            self._loop_ref = self._ref
        elif mode == "position":  # ... and at rest the position loop holds where the profile stopped
            limit = self.gains.max_speed_rpm * RAD_S_PER_RPM
            correction = self._kp_pos * (self._pos_ref - self.theta)
            self._loop_ref = max(-limit, min(limit, correction))
        else:
            self._loop_ref = self._ref
        err = self._loop_ref - self._w_meas
        unclamped = self._kp * (err + self._integral / self._ti)
        if self._ff is not None:
            unclamped += self._feed_forward_nm(self._ff)
        if abs(unclamped) < self._t_lim:  # anti-windup: integrate only while not saturated
            self._integral += err * TS
            self._saturated_s = 0.0
        else:
            self._saturated_s += TS
        return max(-self._t_lim, min(self._t_lim, unclamped))

    def _feed_forward_nm(self, ff: FrictionFeedForward) -> float:
        """The friction compensation's torque for the speed reference now."""
        pct = ff.torque_pct(self._loop_ref / RAD_S_PER_RPM, self.motor.rated_speed_rpm)
        return pct / 100.0 * self.motor.rated_torque_nm

    def _fence_stop(self) -> None:
        """Beyond an overtravel fence that stops: the speed in the direction of travel is forced to zero at once."""
        fence = self.protections.fence
        if fence is None or fence[2] != "stop":
            return
        rev = self.position_rev
        if rev >= fence[1]:
            self._target, self._ref = min(self._target, 0.0), min(self._ref, 0.0)
        elif rev <= fence[0]:
            self._target, self._ref = max(self._target, 0.0), max(self._ref, 0.0)

    def _step(self) -> None:
        # the torque applied now was commanded one period ago (computation delay), then filtered
        t_cmd = self._controller()
        if self._notches:
            for notch in self._notches:
                t_cmd = notch.step(t_cmd)
        if self.watch_vibration:
            self._t_slow += (t_cmd - self._t_slow) * (TS / (VIBRATION_LOWPASS_S + TS))
            self._vibration += ((t_cmd - self._t_slow) ** 2 - self._vibration) * (TS / VIBRATION_AVERAGE_S)
        applied_target = self._t_delayed
        self._t_delayed = t_cmd
        if self._tf > 0:
            self._t_filtered += (applied_target - self._t_filtered) * (TS / (self._tf + TS))
        else:
            self._t_filtered = applied_target
        self._t_applied += (self._t_filtered - self._t_applied) * (TS / (CURRENT_LOOP_S + TS))
        s = self.settings
        if self.mech.coupled:
            state = self._motion_state()
            self.mech.step_coupled(state, self._t_applied, self._brake_nm(), self._load_friction(), TS)
            self.w, self.theta, self._defl, self._defl_rate = state.w, state.theta, state.defl, state.defl_rate
        else:
            torque = self._t_applied - s.load_torque_nm - s.viscous_nm_per_rad_s * self.w
            if s.mechanics.arm_nm or s.mechanics.cogging_nm:
                torque -= self.mech.rigid_extra_nm(self.theta)
            self.w = friction_step(self.w, torque, self._friction_nm(), self.j, TS)
            self.theta += self.w * TS
        counts = math.floor(self.theta / (2 * math.pi) * self.motor.counts_per_rev)
        w_enc = (counts - self._theta_prev_counts) * 2 * math.pi / self.motor.counts_per_rev / TS
        self._theta_prev_counts = counts
        self._w_meas += (w_enc - self._w_meas) * (TS / (SPEED_FILTER_S + TS))
        self._protect()

    def _protect(self) -> None:
        rated = self.motor.rated_torque_nm
        ratio = abs(self._t_applied) / rated
        self._load += (ratio * 100.0 - self._load) * (TS / 0.05)
        self._heat = max(0.0, self._heat + (ratio * ratio - 1.0) * TS)
        if self.mode == "off":
            self._off_s += TS
        elif self.mode == "estop":
            self._estop_s += TS
            if abs(self.w) < 0.5 * RAD_S_PER_RPM or self._estop_s >= ESTOP_MAX_S:
                self.mode = "off"
                self._integral = 0.0
                self._off_s = self._estop_s  # the brake delay runs from the alarm: at most 0.5 s to the brake
        if self.alarm is not None:
            return
        if abs(self.w) > OVERSPEED_X_MAX * self.motor.max_speed_rpm * RAD_S_PER_RPM:
            self.raise_alarm("overspeed")
        elif self._heat > OVERLOAD_LIMIT:
            self.raise_alarm("overload")
        elif self.mode == "position" and abs(self._pos_ref - self.theta) > self.gains.following_limit_rev * 2 * math.pi:
            self.raise_alarm("following_error")
        else:
            self._protections_trip()

    def _protections_trip(self) -> None:
        """The alarms of the drive's own protections: overtravel (a fence that alarms), a locked rotor, a saturated
        speed regulator."""
        p = self.protections
        fence = p.fence
        if fence is not None and fence[2] == "alarm" and not fence[0] <= self.position_rev <= fence[1]:
            self.raise_alarm("overtravel")
            return
        commanded = abs(self._target)
        locked = (
            self.mode in ("speed", "position")
            and commanded > 0.0
            and abs(self.w) < LOCKED_SPEED_SHARE * commanded
            and abs(self._t_applied) >= LOCKED_TORQUE_SHARE * self._t_lim
        )
        self._locked_s = self._locked_s + TS if locked else 0.0
        if p.locked_rotor_s is not None and self._locked_s >= p.locked_rotor_s:
            self.raise_alarm("locked_rotor")
        elif p.saturation_s is not None and self.mode != "off" and self._saturated_s >= p.saturation_s:
            self.raise_alarm("saturation")

    def _motion_state(self) -> MotorState:
        return MotorState(self.w, self.theta, self._defl, self._defl_rate)

    # ----- persistence ---------------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, object]:
        return {
            "time": self.time,
            "w": self.w,
            "theta": self.theta,
            "mode": self.mode,
            "alarm": self.alarm,
            "settings": asdict(self.settings),
            "gains": asdict(self.gains),
        }

    def state(self) -> dict[str, object]:
        """The dynamic state (JSON-safe), to carry the running machine over to another process."""
        out: dict[str, object] = {}
        for name in STATE_FIELDS:
            value = getattr(self, name)
            out[name] = None if isinstance(value, float) and math.isinf(value) else value
        return out

    def restore(self, state: dict[str, object], shift: float = 0.0) -> None:
        """Take over a state(); shift moves its time into this process's clock. Malformed fields are ignored."""
        for name in STATE_FIELDS:
            value = state.get(name)
            if name == "mode":
                if value in ("off", "speed", "torque", "position", "estop"):
                    self.mode = str(value)
            elif name == "alarm":
                if value is None or isinstance(value, str):
                    self.alarm = value
            elif name == "_off_s" and value is None:
                self._off_s = math.inf
            elif isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value):
                setattr(self, name, int(value) if name == "_theta_prev_counts" else float(value))
                if name == "time":
                    self.time += shift
