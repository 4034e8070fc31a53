"""Host-commanded motion with a dead-man: JOG through the profile's roles, keep-alive, limits, safe stop."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from servotool import alarms
from servotool.codec import parse_value, raw_to_eng
from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError

FEATURE = "jog"


def servo_is_on(drive: Drive) -> bool | None:
    """Servo state from the servo_status role (None when the profile has no such role)."""
    entry = drive.profile.role("servo_status")
    if entry is None:
        return None
    raw = drive.read_entries([entry])[0].raw
    bit = next((b for b, name in entry.bits.items() if name.lower() in ("servo_on", "son", "run")), None)
    return bool(raw >> bit & 1) if bit is not None else raw != 0


def keepalive_interval_s(drive: Drive, default_s: float = 0.1) -> float:
    """How often host motion must beat: three times per watchdog period (role comm_timeout), else default_s.

    Raises UsageError when the watchdog is too short to keep any motion alive over a serial link.
    """
    timeout = drive.profile.role("comm_timeout")
    if timeout is None:
        return default_s
    timeout_s = float(raw_to_eng(timeout, drive.read_entries([timeout])[0].raw)) / 1000.0
    if timeout_s <= 0:          # watchdog disabled
        return default_s
    if timeout_s < 0.06:
        raise UsageError(f"the drive's host watchdog {timeout.code} = {timeout_s * 1000:g} ms is too short "
                         "to keep a motion alive over this link (at least 60 ms)")
    return timeout_s / 3


@dataclass(frozen=True)
class JogPlan:
    speed_rpm: float
    direction: int           # +1 forward, -1 reverse
    seconds: float | None    # None: until stopped
    max_speed_rpm: float
    accel_ms: float | None
    travel_rev: float | None  # estimate for a timed jog

    def describe(self) -> str:
        what = "forward" if self.direction > 0 else "reverse"
        more = f" for {self.seconds:g} s (about {self.travel_rev:.2f} rev)" if self.seconds is not None else ""
        ramp = f", ramp {self.accel_ms:g} ms" if self.accel_ms is not None else ""
        return f"JOG {what} at {self.speed_rpm:g} rpm{more}{ramp}"


class Jogger:
    """JOG one drive with a keep-alive; always leaves the motor stopped."""

    def __init__(self, drive: Drive, keepalive_s: float = 0.1) -> None:
        self.drive = drive
        self.profile = drive.profile
        self.jog = self.profile.need_role("jog", FEATURE)
        self.jog_speed = self.profile.need_role("jog_speed", FEATURE)
        self.keepalive = self.profile.role("keepalive")
        self.speed_fb = self.profile.role("speed_feedback")
        self.keepalive_s = keepalive_s
        self.direction = 0
        self._beat = 0
        self._stop_wait_s = 3.0

    def speed_limit(self) -> float:
        """The lowest of: the drive's max-speed parameter, the JOG speed range, the motor's max speed."""
        limits = [raw_to_eng(self.jog_speed, self.jog_speed.max)]
        max_speed = self.profile.role("max_speed")
        if max_speed is not None:
            limits.append(raw_to_eng(max_speed, self.drive.read_entries([max_speed])[0].raw))
        if self.profile.motor is not None:
            limits.append(self.profile.motor.max_speed_rpm)
        return float(min(limits))

    def plan(self, speed_rpm: float, seconds: float | None, max_travel_rev: float | None = None) -> JogPlan:
        """Check everything before any motion: alarm, servo state, speed and travel limits."""
        if speed_rpm == 0 or not math.isfinite(speed_rpm):
            raise UsageError("--speed must be a non-zero number (its sign gives the direction)")
        if seconds is not None and not (math.isfinite(seconds) and seconds > 0):
            raise UsageError("--time must be a number > 0")
        limit = self.speed_limit()
        if abs(speed_rpm) > limit:
            raise UsageError(f"speed {abs(speed_rpm):g} rpm is over the limit {limit:g} rpm "
                             "(drive max-speed parameter, JOG range, motor)")
        parse_value(self.jog_speed, f"{abs(speed_rpm):g}")  # resolution and range of the JOG speed entry
        if self.profile.role("alarm_code") is not None:
            state = alarms.current(self.drive)
            if state.active:
                raise UsageError(f"refusing to move: alarm {state.display} {state.name} is active "
                                 "(see 'servotool alarm', clear it first)")
        if servo_is_on(self.drive):
            raise UsageError("refusing to JOG: the servo is already on (enabled from elsewhere); switch it off first")
        travel = abs(speed_rpm) / 60.0 * seconds if seconds is not None else None
        if max_travel_rev is not None and travel is not None and travel > max_travel_rev:
            raise UsageError(f"a {seconds:g} s JOG at {abs(speed_rpm):g} rpm travels about {travel:.2f} rev, over the "
                             f"--max-travel limit {max_travel_rev:g} rev")
        self.keepalive_s = min(self.keepalive_s, keepalive_interval_s(self.drive))
        accel = self.profile.role("jog_accel")
        accel_ms = raw_to_eng(accel, self.drive.read_entries([accel])[0].raw) if accel is not None else None
        self._stop_wait_s = 1.0 + 2.0 * (float(accel_ms) / 1000.0 if accel_ms is not None else 1.0) * \
            abs(speed_rpm) / (self.profile.motor.rated_speed_rpm if self.profile.motor else 3000.0)
        return JogPlan(abs(speed_rpm), 1 if speed_rpm > 0 else -1, seconds, limit,
                       float(accel_ms) if accel_ms is not None else None, travel)

    def set_speed(self, speed_rpm: float) -> None:
        raw = parse_value(self.jog_speed, f"{abs(speed_rpm):g}")
        current = self.drive.read_entries([self.jog_speed])[0].raw
        if current != raw:  # no needless EEPROM write
            self.drive.write_raw(self.jog_speed, raw)

    def command(self, direction: int) -> None:
        """+1 forward, -1 reverse, 0 stop (ramped by the drive's JOG accel time)."""
        self.direction = (direction > 0) - (direction < 0)
        self.drive.write_raw(self.jog, self.direction)

    def beat(self) -> None:
        """The dead-man keep-alive: without it the drive stops the motor after its timeout."""
        self._beat = (self._beat + 1) & 0xFFFF
        if self.keepalive is not None:
            self.drive.write_raw(self.keepalive, self._beat if self.keepalive.max >= 0xFFFF else 1)
        else:
            self.drive.write_raw(self.jog, self.direction)  # re-sending the command is the keep-alive

    def speed(self) -> float | None:
        if self.speed_fb is None:
            return None
        return float(raw_to_eng(self.speed_fb, self.drive.read_entries([self.speed_fb])[0].raw))

    def stop(self, wait_s: float | None = None) -> None:
        """Command stop and wait (bounded by the ramp) until the motor is at rest, keeping the host alive."""
        self.command(0)
        end = time.monotonic() + (wait_s if wait_s is not None else self._stop_wait_s)
        while self.speed_fb is not None and time.monotonic() < end:
            speed = self.speed()
            if speed is not None and abs(speed) < 3.0:
                break
            self.beat()           # the watchdog keeps running while the drive ramps down
            time.sleep(min(0.05, self.keepalive_s))
        servo = self.profile.role("servo_on")
        if servo is not None:
            self.drive.write_raw(servo, 0)   # leave JOG: the drive stops holding the axis

    def run(self, plan: JogPlan, on_sample: Callable[[float, float | None], None] | None = None,
            command: Callable[[], int | None] | None = None) -> None:
        """Run a planned JOG; `command` (interactive) returns a new direction (+1/-1/0) or None to quit.

        Ctrl-C (KeyboardInterrupt) and any link error stop the motor before propagating.
        """
        self.set_speed(plan.speed_rpm)
        t0 = time.monotonic()
        try:
            self.command(plan.direction if command is None else 0)   # interactive: wait for the first key
            while True:
                elapsed = time.monotonic() - t0
                if plan.seconds is not None and elapsed >= plan.seconds:
                    break
                if command is not None:
                    new = command()
                    if new is None:
                        break
                    if new != self.direction:
                        self.command(new)
                self.beat()
                self.check_tripped()
                if on_sample is not None:
                    on_sample(elapsed, self.speed())
                time.sleep(self.keepalive_s)
        except BaseException:
            self._emergency_stop()
            raise
        self.stop()
        self.check_tripped()

    def check_tripped(self) -> None:
        """A JOG the drive ended with an alarm is a failure, not a finished JOG."""
        if self.profile.role("alarm_code") is None:
            return
        state = alarms.current(self.drive)
        if state.active and alarms.current(self.drive).code == state.code:   # seen twice, not one stray reply
            raise DeviceError(f"the drive stopped the JOG with alarm {state.display} {state.name} "
                              "(see 'servotool alarm')")

    def _emergency_stop(self) -> None:
        try:
            self.stop(wait_s=1.0)
        except DeviceError:
            pass  # the drive's own watchdog stops the motor when the host goes quiet

