"""Host-commanded motion with a dead-man: JOG through the profile's roles, keep-alive, limits, safe stop.

Two routes, chosen by role: a JOG trigger (role jog, speed from jog_speed; its raw values come from the entry's
enum names forward/reverse/stop, else +1/-1/0), or a signed speed reference with servo-on over communication
(roles speed_reference + servo_on).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from servotool import alarms, prereq
from servotool.codec import parse_value, raw_to_eng
from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError
from servotool.params import ram_writes
from servotool.profile import Entry, Profile, status_bit

FEATURE = "jog"
DIRECTION_NAMES = {1: "forward", -1: "reverse", 0: "stop"}


def is_sim_extension(entry: Entry) -> bool:
    """An entry servotool added for its simulator (source "servotool ..."): not on the real drive."""
    return entry.source.strip().lower().startswith("servotool")


def jog_codes(entry: Entry) -> dict[int, int]:
    """Direction (+1/-1/0) -> raw value of a JOG trigger entry."""
    names = {name.split()[0].lower(): raw for raw, name in entry.enum.items() if name.strip()}
    if all(n in names for n in DIRECTION_NAMES.values()):
        return {d: names[n] for d, n in DIRECTION_NAMES.items()}
    return {1: 1, -1: -1, 0: 0}


def jog_direction(entry: Entry, raw: int) -> int:
    """The direction a raw value written to a JOG trigger entry commands (unknown values stop)."""
    codes = jog_codes(entry)
    if codes == {1: 1, -1: -1, 0: 0}:
        return (raw > 0) - (raw < 0)
    return next((d for d, r in codes.items() if r == raw), 0)


@dataclass(frozen=True)
class MotionRoute:
    """How this profile moves the motor over communication: kind 'trigger' or 'speed', and the entries by role."""

    kind: str
    entries: dict[str, Entry]

    @property
    def speed_entry(self) -> Entry:
        return self.entries["jog_speed" if self.kind == "trigger" else "speed_reference"]


ROUTE_ROLES = ("jog", "jog_speed", "speed_reference", "servo_on", "jog_accel", "keepalive", "comm_timeout")


def motion_route(profile: Profile, feature: str = FEATURE) -> MotionRoute:
    """The profile's motion route; one clear line when it has none."""
    found = {r: e for r in ROUTE_ROLES if (e := profile.role(r)) is not None}
    if "jog" in found and "jog_speed" in found:
        kind = "trigger"
        found.pop("speed_reference", None)
    elif "speed_reference" in found and "servo_on" in found:
        kind = "speed"
        found.pop("jog", None)
    else:
        raise UsageError(f"{feature} needs role 'jog' with 'jog_speed', or 'speed_reference' with 'servo_on', "
                         f"which profile {profile.id} does not map")
    return MotionRoute(kind, found)


@dataclass(frozen=True)
class MotionCaveats:
    """What is not known to work on a real drive: unverified route entries, and a missing drive-side watchdog."""

    unverified: tuple[tuple[str, Entry, str], ...]   # (role, entry, reason); role "setup" for motion_setup items
    drive_timeout: Entry | None                       # None: nothing on the drive stops the motor if the host dies
    power_cycle: tuple[Entry, ...] = ()               # motion_setup entries that take effect after a power cycle

    def lines(self) -> list[str]:
        out = [f"{e.code} ({role}): {reason}" for role, e, reason in self.unverified]
        if self.power_cycle:
            codes = ", ".join(e.code for e in self.power_cycle)
            out.append(f"{codes} take effect only after a power cycle: if they were changed since the drive was "
                       "switched on, it will not move")
        if self.drive_timeout is None:
            out.append("this drive has no communication timeout: if this program dies (kill, crash, cable), the "
                       "motor keeps running until stopped at the drive; Ctrl-C still stops it")
        return out


def motion_caveats(profile: Profile, feature: str = FEATURE) -> MotionCaveats:
    """Unverified entries of the motion route (with their reasons) and the drive-side watchdog, if real."""
    route = motion_route(profile, feature)
    unverified = []
    for role, e in route.entries.items():
        reason = e.unverified or ("a servotool simulator extension, not in the manual" if is_sim_extension(e) else "")
        if reason:
            unverified.append((role, e, reason))
    setup = prereq.requirements(profile)
    unverified += [("setup", r.entry, r.item.unverified) for r in setup if r.item.unverified]
    timeout = route.entries.get("comm_timeout")
    return MotionCaveats(tuple(unverified), timeout if timeout is not None and not is_sim_extension(timeout) else None,
                         tuple(r.entry for r in setup if r.entry.effect == "power_cycle"))


def check_setup(drive: Drive, feature: str = FEATURE,
                effective_of: Callable[[list[Entry]], list[int]] | None = None) -> None:
    """Refuse host motion while the drive lacks the profile's motion_setup settings (one line naming each)."""
    def value_of(entries: list[Entry]) -> list[int]:
        return [r.raw for r in drive.read_entries(entries)]

    prereq.check(drive.profile, "JOG" if feature == FEATURE else feature, value_of, effective_of)


def servo_is_on(drive: Drive) -> bool | None:
    """Servo state from the servo_status role (None when the profile has no such role)."""
    entry = drive.profile.role("servo_status")
    if entry is None:
        return None
    raw = drive.read_entries([entry])[0].raw
    bit = status_bit(entry, "servo_on")
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

    def __init__(self, drive: Drive, keepalive_s: float = 0.1, feature: str = FEATURE) -> None:
        self.drive = drive
        self.profile = drive.profile
        self.route = motion_route(self.profile, feature)
        check_setup(drive, feature)    # before anything is written: a drive not set up would ignore or misread us
        self.speed_entry = self.route.speed_entry
        self.jog = self.route.entries.get("jog")
        self.servo = self.route.entries.get("servo_on")
        self.keepalive = self.route.entries.get("keepalive")
        self.speed_fb = self.profile.role("speed_feedback")
        self.keepalive_s = keepalive_s
        self.direction = 0
        self.speed_rpm = 0.0
        self._enabled = False          # speed route: servo switched on by us
        self._saved_reference: int | None = None
        self._beat = 0
        self._stop_wait_s = 3.0

    def speed_limit(self) -> float:
        """The lowest of: the drive's max-speed parameter, the JOG speed range, the motor's max speed."""
        limits = [raw_to_eng(self.speed_entry, self.speed_entry.max)]
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
        parse_value(self.speed_entry, f"{abs(speed_rpm):g}")  # resolution and range of the speed entry
        if self._speed_raw(abs(speed_rpm)) == 0:
            raise UsageError(f"speed {abs(speed_rpm):g} rpm rounds to 0 in {self.speed_entry.code}: nothing would move")
        if self.profile.role("alarm_code") is not None:
            state = alarms.current(self.drive)
            if state.active:
                raise UsageError(f"refusing to move: alarm {state.display} {state.name} is active "
                                 "(see 'servotool alarm', clear it first)")
        if self.servo_already_on():
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

    def servo_already_on(self) -> bool:
        """Servo on from elsewhere: the status word says so, or a servo-on held in a parameter is set."""
        return bool(servo_is_on(self.drive)) or (
            self.servo is not None and self.servo.readable and self.servo.cls == "Pn"
            and self.drive.read_entries([self.servo])[0].raw != 0)

    def _speed_raw(self, signed_rpm: float) -> int:
        e = self.speed_entry
        return max(e.min, min(e.max, round(signed_rpm / e.scale)))

    def set_speed(self, speed_rpm: float) -> None:
        """The speed of the following moves (rpm, sign ignored); a running speed-route move changes at once."""
        self.speed_rpm = abs(speed_rpm)
        if self.route.kind == "trigger":
            raw = self._speed_raw(self.speed_rpm)
            if self.drive.read_entries([self.speed_entry])[0].raw != raw:  # no needless EEPROM write
                self.drive.write_raw(self.speed_entry, raw)
        elif self._enabled and self.direction:
            self.drive.write_raw(self.speed_entry, self._speed_raw(self.direction * self.speed_rpm))

    def command(self, direction: int) -> None:
        """+1 forward, -1 reverse, 0 stop (ramped by the drive's JOG/speed accel time)."""
        self.direction = (direction > 0) - (direction < 0)
        if self.jog is not None:
            self.drive.write_raw(self.jog, jog_codes(self.jog)[self.direction])
            return
        assert self.servo is not None
        if self.direction and not self._enabled:
            # A reference held in a parameter (e.g. a signed JOG speed) would run at once on enable: zero it first.
            if self._saved_reference is None and self.speed_entry.readable:
                self._saved_reference = self.drive.read_entries([self.speed_entry])[0].raw
            self.drive.write_raw(self.speed_entry, self._speed_raw(0))
            self.drive.write_raw(self.servo, 1)
            self._enabled = True
        if self._enabled:
            self.drive.write_raw(self.speed_entry, self._speed_raw(self.direction * self.speed_rpm))

    def beat(self) -> None:
        """The dead-man keep-alive: without it the drive stops the motor after its timeout."""
        self._beat = (self._beat + 1) & 0xFFFF
        if self.keepalive is not None:
            self.drive.write_raw(self.keepalive, self._beat if self.keepalive.max >= 0xFFFF else 1)
        elif self.jog is not None:
            self.drive.write_raw(self.jog, jog_codes(self.jog)[self.direction])  # re-sending the command
        elif self._enabled and self.servo is not None:
            self.drive.write_raw(self.servo, 1)      # re-sending servo-on (no EEPROM write of the reference)

    def leave(self) -> None:
        """Servo off (the drive stops holding the axis) and put back a parameter-held speed reference."""
        if self.servo is not None:
            self.drive.write_raw(self.servo, 0)
        self._enabled = False
        if self._saved_reference is not None:
            if self.drive.read_entries([self.speed_entry])[0].raw != self._saved_reference:
                self.drive.write_raw(self.speed_entry, self._saved_reference)
            self._saved_reference = None

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
        self.leave()

    def run(self, plan: JogPlan, on_sample: Callable[[float, float | None], None] | None = None,
            command: Callable[[], int | None] | None = None) -> None:
        """Run a planned JOG; `command` (interactive) returns a new direction (+1/-1/0) or None to quit.

        Ctrl-C (KeyboardInterrupt) and any link error stop the motor before propagating. The JOG's own writes
        stay out of EEPROM where the drive has a switch.
        """
        with ram_writes(self.drive):
            self._run(plan, on_sample, command)

    def _run(self, plan: JogPlan, on_sample: Callable[[float, float | None], None] | None = None,
             command: Callable[[], int | None] | None = None) -> None:
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
        state = alarms.confirmed(self.drive)
        if state is not None:
            raise DeviceError(f"the drive stopped the JOG with alarm {state.display} {state.name} "
                              "(see 'servotool alarm')")

    def _emergency_stop(self) -> None:
        try:
            self.stop(wait_s=1.0)
        except DeviceError:
            pass  # the drive's own watchdog stops the motor when the host goes quiet

