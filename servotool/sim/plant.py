"""Physics and servo control loops behind the simulated drive (no Modbus here).

Rigid motor + load: J = Jm * (1 + load_ratio), with Coulomb friction (and stiction at rest), viscous friction and a
constant load torque (gravity axis). Sign convention: J dw/dt = T - Tc*sign(w) - B*w - Tg.
The drive's speed PI computes its gain from the *configured* inertia ratio, as real drives do, so a wrong ratio shows
as a sluggish, overshooting or oscillating loop. The loop runs at a 125 us control period with a one-sample delay,
a speed-feedback filter and the torque-command filter from the drive's parameters.

Time is integrated only when asked (`advance_to`), so an idle simulator costs nothing.
"""

from __future__ import annotations

import math
import random
import time
from dataclasses import asdict, dataclass
from typing import Protocol

from servotool.profile import Motor as MotorData  # the profile's motor data drives the plant directly

TS = 125e-6                 # control period, s
SPEED_FILTER_S = 0.25e-3    # speed feedback low-pass
CURRENT_LOOP_S = 0.2e-3     # the current loop's lag between torque command and torque (about 800 Hz)
MAX_GAP_S = 20.0            # integrate at most this much at once; beyond it the state is carried over
RAD_S_PER_RPM = 2 * math.pi / 60
OVERLOAD_LIMIT = 8.0        # I^2t budget: 300 % torque trips after 1 s, 200 % after 2.7 s
FOLLOWING_LIMIT_REV = 3.0


class Clock(Protocol):
    def now(self) -> float: ...


class RealClock:
    """Monotonic wall clock."""

    def now(self) -> float:
        return time.monotonic()


class VirtualClock:
    """A clock that moves only when told: deterministic tests and fast benchmarks."""

    def __init__(self, start: float = 0.0) -> None:
        self.t = start

    def now(self) -> float:
        return self.t

    def advance(self, dt: float) -> float:
        self.t += dt
        return self.t


@dataclass(frozen=True)
class PlantSettings:
    """The machine's true properties (SI units)."""

    load_ratio: float = 0.0
    coulomb_nm: float = 0.0
    viscous_nm_per_rad_s: float = 0.0
    load_torque_nm: float = 0.0
    noise: float = 0.0       # speed std = noise * 1000 rpm, torque std = noise * 100 % of rated
    seed: int = 1


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
    jog_accel_ms: float = 200.0     # time from 0 to rated speed


class Plant:
    """Motor, load and the drive's control loops, integrated on demand."""

    def __init__(self, motor: MotorData, settings: PlantSettings, gains: DriveGains, start_time: float = 0.0) -> None:
        self.motor = motor
        self.time = start_time
        self.w = 0.0               # rad/s
        self.theta = 0.0           # rad
        self.mode = "off"          # off | speed | torque | position | estop
        self.alarm: str | None = None
        self._w_meas = 0.0
        self._theta_prev_counts = 0
        self._integral = 0.0
        self._t_cmd = 0.0          # torque command before the filter, N*m
        self._t_filtered = 0.0     # after the torque-command filter
        self._t_applied = 0.0      # produced by the current loop
        self._t_delayed = 0.0
        self._ref = 0.0            # ramped speed reference, rad/s
        self._target = 0.0         # speed command, rad/s
        self._torque_target = 0.0  # N*m (torque mode)
        self._pos_ref = 0.0
        self._heat = 0.0
        self._load = 0.0
        self.set_settings(settings)
        self.set_gains(gains)

    # ----- configuration -------------------------------------------------------------------------------------
    def set_settings(self, settings: PlantSettings) -> None:
        self.settings = settings
        self.j = self.motor.jm * (1.0 + settings.load_ratio)
        self._rng = random.Random(settings.seed)

    def set_gains(self, gains: DriveGains) -> None:
        self.gains = gains
        j_conf = self.motor.jm * (1.0 + gains.inertia_ratio_configured)
        self._kp = 2 * math.pi * gains.speed_gain_hz * j_conf
        self._ti = max(gains.speed_integral_ms, 0.1) / 1000.0
        self._tf = max(gains.torque_filter_ms, 0.0) / 1000.0
        self._t_lim = gains.torque_limit_pct / 100.0 * self.motor.rated_torque_nm
        self._ramp = self.motor.rated_speed_rpm * RAD_S_PER_RPM / max(gains.jog_accel_ms / 1000.0, 1e-3)

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
    def speed_command_rpm(self) -> float:
        return self._ref / RAD_S_PER_RPM if self.mode in ("speed", "estop") else 0.0

    @property
    def position_rev(self) -> float:
        return self.theta / (2 * math.pi)

    @property
    def position_counts(self) -> int:
        return math.floor(self.position_rev * self.motor.counts_per_rev)

    @property
    def following_error_counts(self) -> int:
        if self.mode != "position":
            return 0
        return round((self._pos_ref - self.theta) / (2 * math.pi) * self.motor.counts_per_rev)

    @property
    def load_rate_pct(self) -> float:
        return self._load

    # ----- integration ---------------------------------------------------------------------------------------
    def advance_to(self, t: float) -> None:
        """Integrate from the last time to t with the fixed control period."""
        dt_total = t - self.time
        if dt_total <= 0:
            return
        if dt_total > MAX_GAP_S:
            self._cool(dt_total - MAX_GAP_S)
            self.time = t - MAX_GAP_S  # an idle gap: the state carries over, only the recent part is integrated
        if self.mode == "off" and self.w == 0.0 and abs(self.settings.load_torque_nm) <= self.settings.coulomb_nm:
            self._cool(t - self.time)
            self.time = t              # at rest, nothing acting: nothing to integrate
            self._w_meas = 0.0
            self._t_applied = self._t_filtered = self._t_cmd = self._t_delayed = 0.0
            self._load = 0.0
            return
        steps = int((t - self.time) / TS + 1e-9)
        for _ in range(steps):
            self._step()
        self.time += steps * TS        # the remainder (< one period) is integrated by the next call

    def _cool(self, seconds: float) -> None:
        """The motor's I^2t heat over time not integrated step by step (no current: it falls by 1 per second)."""
        self._heat = max(0.0, self._heat - seconds)

    def _controller(self) -> float:
        """Torque command of this control period (before the filter)."""
        mode = self.mode
        if mode == "off":
            self._integral = 0.0
            return 0.0
        if mode == "torque":
            return self._torque_target
        if mode == "position":
            self._target = self.gains.position_gain_per_s * (self._pos_ref - self.theta)
            self._ref = self._target
        else:
            step = self._ramp * TS if mode == "speed" else math.inf
            diff = self._target - self._ref
            self._ref += max(-step, min(step, diff))
        err = self._ref - self._w_meas
        unclamped = self._kp * (err + self._integral / self._ti)
        if abs(unclamped) < self._t_lim:  # anti-windup: integrate only while not saturated
            self._integral += err * TS
        return max(-self._t_lim, min(self._t_lim, unclamped))

    def _step(self) -> None:
        # the torque applied now was commanded one period ago (computation delay), then filtered
        t_cmd = self._controller()
        applied_target = self._t_delayed
        self._t_delayed = t_cmd
        if self._tf > 0:
            self._t_filtered += (applied_target - self._t_filtered) * (TS / (self._tf + TS))
        else:
            self._t_filtered = applied_target
        self._t_applied += (self._t_filtered - self._t_applied) * (TS / (CURRENT_LOOP_S + TS))
        s = self.settings
        torque = self._t_applied - s.load_torque_nm - s.viscous_nm_per_rad_s * self.w
        w = self.w
        if w == 0.0:
            if abs(torque) <= s.coulomb_nm:
                torque = 0.0                               # stiction holds
            else:
                torque -= math.copysign(s.coulomb_nm, torque)
            w_new = w + torque / self.j * TS
        else:
            w_new = w + (torque - math.copysign(s.coulomb_nm, w)) / self.j * TS
            if (w_new > 0) != (w > 0):                     # friction stops the motor, it does not reverse it
                w_new = 0.0 if abs(torque) <= s.coulomb_nm else w_new
        self.w = w_new
        self.theta += w_new * TS
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
        if self.mode == "estop" and abs(self.w) < 0.5 * RAD_S_PER_RPM:
            self.mode = "off"
            self._integral = 0.0
        if self.alarm is not None:
            return
        if abs(self.w) > 1.1 * self.gains.max_speed_rpm * RAD_S_PER_RPM:
            self.raise_alarm("overspeed")
        elif self._heat > OVERLOAD_LIMIT:
            self.raise_alarm("overload")
        elif self.mode == "position" and abs(self._pos_ref - self.theta) > FOLLOWING_LIMIT_REV * 2 * math.pi:
            self.raise_alarm("following_error")

    # ----- persistence ---------------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, object]:
        return {"time": self.time, "w": self.w, "theta": self.theta, "mode": self.mode, "alarm": self.alarm,
                "settings": asdict(self.settings), "gains": asdict(self.gains)}
