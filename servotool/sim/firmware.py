"""The simulated drive's firmware: connects register writes/reads to the plant.

It runs only when a request arrives: the plant is integrated up to "now", with scheduled events (watchdog expiry,
identification phases) applied at their exact simulated times on the way. Roles, not vendor codes, say which
entry does what, so any profile with the roles gets the behaviour.

Servo on by command puts the drive in its control mode (the plant's position mode): standing still holds position
through the position loop, so a load the motor cannot hold ends in the following-error alarm; a host speed reference
runs under speed control and the hold resumes where it returns to zero. JOG, a test function, runs under speed
control throughout, its stop included, as real drives' JOG does (a position hold there would also make a badly
mis-tuned speed loop oscillate at every JOG stop of the inertia identification).
The drive stays powered between CLI invocations: the running state (latched alarm, servo and motion state, position,
I^2t) is kept in the state file with the parameters; a power cycle (`sim serve` start, `sim reset --power-cycle`, a
soft reset) starts it afresh.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any

from servotool.clock import Clock, RealClock
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.gain_units import to_canonical
from servotool.model.profile import Entry, Motor, Profile
from servotool.model.roles import jog_direction, status_bit
from servotool.model.setup import requirements
from servotool.sim.device import SimulatedDrive
from servotool.sim.plant import (
    BRAKE_HOLD_X_RATED,
    FOLLOWING_LIMIT_REV,
    DriveGains,
    Plant,
    PlantSettings,
)
from servotool.sim.registers import MACHINE_STATE_KEY

DEFAULT_MOTOR = Motor(source="servotool default: 400 W, 3000 rpm")
# Simulator assumption for drives whose manual documents no communication timeout (no comm_timeout role): host
# motion stops (ramped, no alarm) when no motion-role write arrives for this long. A real drive of that kind keeps
# running; servotool says so before moving it.
DEFAULT_HOST_TIMEOUT_MS = 500.0
STATUS_BITS = {"servo_on": 0, "fault": 1, "warning": 2, "moving": 3, "jog": 4, "identifying": 5}
FIRMWARE_MODES = ("off", "jog", "speed", "servo", "ident", "stopping")
COUNT_UNITS = ("counts", "count", "pulse", "pulses", "p")


@dataclass
class Identification:
    """Drive-side offline inertia identification in progress (a torque-driven back-and-forth move)."""

    torque_pct: float
    max_rev: float
    top_rpm: float
    start_pos: float
    phase: int = 0          # 0 accel fwd, 1 decel fwd, 2 accel rev, 3 decel rev
    phase_t0: float = 0.0
    phase_w0: float = 0.0
    estimates: list[float] | None = None


class Firmware:
    """Drive behaviour of one SimulatedDrive: JOG, speed command, servo on, watchdog, alarms, identification."""

    def __init__(self, drive: SimulatedDrive, clock: Clock | None = None) -> None:
        self.drive = drive
        self.profile: Profile = drive.profile
        self.clock = clock or RealClock()
        self.motor = self.profile.motor or DEFAULT_MOTOR
        self._setup = requirements(self.profile)
        self._power_on()
        self._seq: int | None = None  # which stored machine state this process's state is (None: not stored)
        self._take_machine_state()
        drive.on_read.append(lambda _d: self.update())
        drive.on_param_change.append(self._param_changed)
        drive.on_reload.append(self._reloaded)
        drive.bank.before_write.append(self._store_machine_state)
        soft_reset = drive.handlers.get("soft_reset")
        motion = {"jog": self._fn_jog, "speed_reference": self._fn_speed, "servo_on": self._fn_servo,
                  "keepalive": self._fn_keepalive}
        drive.handlers.update({
            **motion, "alarm_reset": self._fn_alarm_reset, "inertia_id": self._fn_inertia_id,
            "soft_reset": lambda d, e, raw: self._fn_soft_reset(soft_reset, d, e, raw),
        })
        # Motion roles may sit on parameters (a signed JOG speed, a forced-DI word): their writes act too.
        self._param_motion: dict[str, list[Callable[[SimulatedDrive, Entry, int], None]]] = {}
        for role, code in self.profile.roles.items():
            entry = self.profile.entry(code)
            if role in motion and entry is not None and entry.cls != "Fn":
                self._param_motion.setdefault(entry.code.upper(), []).append(motion[role])
        self.update()

    def _power_on(self) -> None:
        """The state right after power on: servo off, no alarm, position counter at zero, motor cold."""
        self.plant = Plant(self.motor, self._plant_settings(), self._gains(), start_time=self.clock.now())
        self.mode = "off"        # off | jog | speed | servo | ident | stopping (host lost, no alarm kind)
        self.jog_dir = 0
        self.last_host = self.clock.now()
        self.ident: Identification | None = None
        self._recorded = False  # whether the alarm latched now is already in the history

    # ----- the running state, shared with other processes through the state file -----------------------------
    def _store_machine_state(self) -> None:
        """Put this process's running state into the state file about to be written."""
        stored = self.drive.bank.extra.get(MACHINE_STATE_KEY)
        seq = stored.get("seq", 0) if isinstance(stored, dict) else 0
        self._seq = (seq if isinstance(seq, int) else 0) + 1
        self.drive.bank.extra[MACHINE_STATE_KEY] = {
            "seq": self._seq, "wall_offset": self.clock.wall() - self.clock.now(), "plant": self.plant.state(),
            "mode": self.mode, "jog_dir": self.jog_dir, "last_host": self.last_host, "recorded": self._recorded,
            "ident": asdict(self.ident) if self.ident is not None else None,
        }

    def _take_machine_state(self) -> None:
        """Continue from the running state another process stored (or start afresh after a power cycle)."""
        stored = self.drive.bank.extra.get(MACHINE_STATE_KEY)
        if not isinstance(stored, dict):
            if self._seq is not None:          # stored before, gone now: the drive was power-cycled
                self._power_on()
                self._seq = None
            return
        if stored.get("seq") == self._seq:
            return                             # our own state (the file changed for another reason)
        self._power_on()
        offset = stored.get("wall_offset")
        shift = float(offset) - (self.clock.wall() - self.clock.now()) if isinstance(offset, (int, float)) else 0.0
        plant = stored.get("plant")
        if isinstance(plant, dict):
            self.plant.restore(plant, shift)
        if stored.get("mode") in FIRMWARE_MODES:
            self.mode = str(stored["mode"])
        self.jog_dir = _int(stored.get("jog_dir"), 0)
        last_host = stored.get("last_host")
        if isinstance(last_host, (int, float)):
            self.last_host = float(last_host) + shift
        self._recorded = stored.get("recorded") is True
        self.ident = _identification(stored.get("ident"), shift)
        if self.mode == "ident" and self.ident is None:
            self.mode = "off"
            self.plant.set_mode("off")
        seq = stored.get("seq")
        self._seq = seq if isinstance(seq, int) else None

    # ----- settings ------------------------------------------------------------------------------------------
    def _plant_settings(self) -> PlantSettings:
        s = self.drive.settings
        rated = self.motor.rated_torque_nm
        return PlantSettings(
            load_ratio=float(s["load_ratio"]), coulomb_nm=float(s["friction"]) * rated,
            viscous_nm_per_rad_s=float(s["viscous"]) * rated, load_torque_nm=float(s["load_torque"]) * rated,
            noise=float(s["noise"]), seed=int(s["seed"]),
            brake_nm=BRAKE_HOLD_X_RATED * rated if s["brake"] else 0.0)

    def _eng(self, role: str, default: float) -> float:
        entry = self.profile.role(role)
        if entry is None:
            return default
        return float(raw_to_eng(entry, self.drive.bank.effective_value(entry.code)))

    def _gain(self, role: str, default: float) -> float:
        entry = self.profile.role(role)
        return default if entry is None else to_canonical(role, entry, self._eng(role, default))

    def _gains(self) -> DriveGains:
        ratio_entry = self.profile.role("inertia_ratio")
        ratio = self.profile.load_ratio_from_param(self._eng("inertia_ratio", 0.0)) if ratio_entry else 0.0
        integral = self.profile.role("speed_loop_integral")
        return DriveGains(
            inertia_ratio_configured=max(0.0, ratio),
            speed_gain_hz=self._gain("speed_loop_gain", 40.0),
            speed_integral_ms=self._eng("speed_loop_integral", 20.0) if integral else 20.0,
            position_gain_per_s=self._gain("position_loop_gain", 40.0),
            torque_filter_ms=self._gain("torque_filter", 0.5),
            torque_limit_pct=min(self._eng("torque_limit_fwd", 300.0), self._eng("torque_limit_rev", 300.0)),
            max_speed_rpm=min(self._eng("max_speed", self.motor.max_speed_rpm), self.motor.max_speed_rpm * 1.2),
            jog_accel_ms=max(1.0, self._eng("jog_accel", 200.0)),
            following_limit_rev=self._following_limit_rev(),
        )

    def _following_limit_rev(self) -> float:
        """The drive's following-error alarm limit in motor revolutions (simulator default without a parameter)."""
        entry = self.profile.role("following_error_limit")
        if entry is None or entry.unit.lower() not in (*COUNT_UNITS, "rev"):
            return FOLLOWING_LIMIT_REV
        limit = self._eng("following_error_limit", 0.0)
        if entry.unit.lower() != "rev":
            limit /= self.motor.counts_per_rev
        return limit if limit > 0 else FOLLOWING_LIMIT_REV

    def _param_changed(self, drive: SimulatedDrive, entry: Entry, raw: int) -> None:
        self.update()
        self.plant.set_gains(self._gains())
        for handler in self._param_motion.get(entry.code.upper(), []):
            handler(drive, entry, raw)

    def reconfigure(self) -> None:
        """Apply changed simulated-machine settings (sim config)."""
        self.plant.set_settings(self._plant_settings())

    def _reloaded(self, _drive: SimulatedDrive) -> None:
        """Another process changed the drive's state (sim config, sim reset, another server): take it over."""
        self._take_machine_state()
        self.plant.set_settings(self._plant_settings())
        self.plant.set_gains(self._gains())

    @property
    def alarm_history(self) -> list[int]:
        """Latest first; kept in the state file like a drive's fault log."""
        return self.drive.bank.extra.setdefault("alarm_history", [])

    # ----- time ----------------------------------------------------------------------------------------------
    def _timeout_s(self) -> float:
        return self._eng("comm_timeout", DEFAULT_HOST_TIMEOUT_MS) / 1000.0

    def update(self) -> None:
        """Integrate the plant up to now, applying the watchdog and identification on the way; refresh monitors."""
        now = self.clock.now()
        if self._watched():
            expiry = self.last_host + self._timeout_s()
            if expiry < now:
                self.plant.advance_to(expiry)
                self._host_lost()
        if self.ident is not None:
            self._advance_identification(now)
        if self.mode == "stopping":
            self._advance_stop(now)
        self.plant.advance_to(now)
        if self.plant.alarm is not None:
            if self.mode != "off":
                self.mode = "off"
                self.ident = None
            self._record_alarm()       # also alarms raised with the servo off
        self._refresh_monitors()

    def _watched(self) -> bool:
        """Whether the host watchdog runs: a documented one (comm_timeout role) whenever the host holds the servo;
        the simulator's assumed one (drives that document none) only while the host commands motion, so a servo
        switched on by a plain parameter write stays on, as it would on the real drive."""
        if self.profile.role("comm_timeout") is not None:
            return self.mode in ("jog", "speed", "servo")
        return self.mode in ("jog", "speed") and (self.jog_dir != 0 or self.plant.target_rpm != 0.0)

    def _host_lost(self) -> None:
        """The watchdog expired: stop with the profile's communication alarm (ramp down quietly if it has none)."""
        servo = self.profile.role("servo_on")
        if servo is not None and servo.cls == "Pn":
            self.drive.bank.apply_parameter(servo, 0)   # a servo-on held in a parameter drops with the servo
            self.drive.bank.save()
        if self.profile.alarm_of_kind("comm_timeout") is not None:
            self._trip("comm_timeout")
            return
        self.plant.set_speed_command(0.0)
        self.jog_dir = 0
        self.mode = "stopping"

    def _advance_stop(self, now: float) -> None:
        t = self.plant.time
        while self.mode == "stopping" and t < now:
            t = min(now, t + 0.01)
            self.plant.advance_to(t)
            if abs(self.plant.true_speed_rpm) < 1.0:
                self.plant.set_mode("off")
                self.mode = "off"

    def _trip(self, kind: str) -> None:
        self.plant.raise_alarm(kind)
        self.mode = "off"
        self.ident = None
        self._record_alarm()

    def _alarm_code(self) -> int:
        name = self.plant.alarm
        if name is None:
            return 0
        # A trip the profile lists no alarm for reports a code outside its list, so it shows as unknown
        # rather than borrowing some unrelated alarm's name.
        alarm = self.profile.alarm_of_kind(name)
        return alarm.code if alarm is not None else 0xFF

    def _record_alarm(self) -> None:
        """Enter the latched alarm in the history once (it stays latched until a reset clears it)."""
        code = self._alarm_code()
        if code and not self._recorded:
            self.alarm_history.insert(0, code)
            del self.alarm_history[8:]
            self.drive.bank.save()
            self._recorded = True

    # ----- functions (Fn writes) -----------------------------------------------------------------------------
    def _host_alive(self) -> None:
        self.last_host = self.clock.now()

    def _motion_allowed(self) -> bool:
        return self.plant.alarm is None

    def _set_up_for_host_motion(self) -> bool:
        """The profile's motion_setup, by the values in effect: without it a real drive ignores (or does something
        else with) a host JOG or servo-on, so the simulated one does not move either."""
        return all(r.met(self.drive.bank.effective_value(r.entry.code)) for r in self._setup)

    def _fn_keepalive(self, _d: SimulatedDrive, _e: Entry, _raw: int) -> None:
        self.update()
        self._host_alive()

    def _fn_jog(self, _d: SimulatedDrive, entry: Entry, raw: int) -> None:
        self.update()
        self._host_alive()
        direction = jog_direction(entry, raw)
        if direction == 0:
            if self.mode == "jog":       # stop, but stay excited (holding) until JOG is left with servo off
                self.plant.set_speed_command(0.0)
                self.jog_dir = 0
                if self.profile.role("servo_on") is None:
                    self.mode = "stopping"   # nothing to leave JOG with: the drive switches off once at rest
            return
        if not self._motion_allowed() or self.mode not in ("off", "jog", "stopping"):
            return
        if self.mode != "jog" and not self._set_up_for_host_motion():
            return
        if self.mode == "off":
            self.plant.set_mode("speed")
        self.mode = "jog"
        self.jog_dir = direction
        self.plant.set_speed_command(direction * self._eng("jog_speed", 100.0))

    def _fn_speed(self, _d: SimulatedDrive, entry: Entry, raw: int) -> None:
        self.update()
        self._host_alive()
        if self.mode in ("servo", "speed"):
            self.mode = "speed"
            self.plant.set_speed_command(float(raw_to_eng(entry, raw)))

    def _fn_servo(self, _d: SimulatedDrive, _e: Entry, raw: int) -> None:
        self.update()
        self._host_alive()
        if raw and self._motion_allowed() and self.mode == "off" and self._set_up_for_host_motion():
            self.plant.set_mode("position")
            self.plant.set_speed_command(0.0)
            self.mode = "servo"
        elif not raw and self.mode in ("servo", "speed", "jog", "stopping"):
            self.plant.set_mode("off")
            self.mode = "off"

    def _fn_alarm_reset(self, _d: SimulatedDrive, _e: Entry, raw: int) -> None:
        self.update()
        if raw:
            self.plant.clear_alarms()
            self._recorded = self.plant.alarm is not None
        self._refresh_monitors()

    def _fn_soft_reset(self, original: Any, drive: SimulatedDrive, entry: Entry, raw: int) -> None:
        """A soft reset reboots the drive: parameters take effect and the running state starts afresh."""
        if original is not None:
            original(drive, entry, raw)
        if raw == entry.trigger:
            self._power_on()
            self.plant.set_gains(self._gains())

    def _fn_inertia_id(self, _d: SimulatedDrive, _e: Entry, raw: int) -> None:
        self.update()
        if not raw:
            if self.ident is not None:
                self.ident = None
                self.plant.set_mode("off")
                self.mode = "off"
            return
        if not self._motion_allowed() or self.mode != "off":
            return
        torque = self._eng("inertia_id_torque", 50.0)
        max_rev = self._eng("inertia_id_travel", 2.0)
        top = min(600.0, self.motor.rated_speed_rpm / 3)
        self.ident = Identification(torque, max_rev, top, self.plant.position_rev, phase_t0=self.clock.now(),
                                    estimates=[])
        self.plant.set_mode("torque")
        self.plant.set_torque_command(torque)
        self.mode = "ident"

    # ----- identification ------------------------------------------------------------------------------------
    def _advance_identification(self, now: float) -> None:
        """Step in small slices so phase switches happen when the speed crosses its targets."""
        ident = self.ident
        assert ident is not None
        t = self.plant.time
        while ident is self.ident and t < now:
            t = min(now, t + 0.002)
            self.plant.advance_to(t)
            w = self.plant.true_speed_rpm
            travel = abs(self.plant.position_rev - ident.start_pos)
            if travel > ident.max_rev or self.plant.alarm is not None:
                self._trip("inertia_id_failed")
                return
            if ident.phase in (0, 2) and abs(w) >= ident.top_rpm:
                self._phase_done(ident, t, w, next_torque=-ident.torque_pct if ident.phase == 0 else ident.torque_pct)
            elif ident.phase in (1, 3) and (w <= 0 if ident.phase == 1 else w >= 0):
                self._phase_done(ident, t, w, next_torque=-ident.torque_pct if ident.phase == 1 else 0.0)
                if ident.phase == 4:
                    self._finish_identification(ident)
                    return

    def _phase_done(self, ident: Identification, t: float, w: float, next_torque: float) -> None:
        dt = t - ident.phase_t0
        dw = abs(w - ident.phase_w0) * 2 * math.pi / 60
        if dt > 0 and dw > 0:
            torque_nm = ident.torque_pct / 100 * self.motor.rated_torque_nm
            assert ident.estimates is not None
            ident.estimates.append(torque_nm * dt / dw)
        ident.phase += 1
        ident.phase_t0 = t
        ident.phase_w0 = w
        self.plant.set_torque_command(next_torque)

    def _finish_identification(self, ident: Identification) -> None:
        """Accel and decel estimates average out Coulomb friction; the result goes into the inertia ratio."""
        self.plant.set_mode("off")
        self.mode = "off"
        self.ident = None
        est = ident.estimates or []
        jm = self.motor.rotor_inertia_kgcm2 * 1e-4
        if len(est) < 4:
            self._trip("inertia_id_failed")
            return
        ratio = sum(est) / len(est) / jm - 1.0
        entry = self.profile.role("inertia_ratio")
        if entry is None:
            return
        raw = eng_to_raw(entry, self.profile.param_from_load_ratio(max(0.0, ratio)))
        self.drive.bank.apply_parameter(entry, raw)
        self.plant.set_gains(self._gains())
        self.drive.bank.save()

    # ----- monitors ------------------------------------------------------------------------------------------
    def _set(self, role: str, eng: float) -> None:
        entry = self.profile.role(role)
        if entry is None or entry.cls == "Pn" or entry.cls == "Fn":
            return
        self.drive.bank.set_live(entry.code, eng_to_raw(entry, eng, clamp=False))

    def _refresh_monitors(self) -> None:
        p = self.plant
        self._set("speed_feedback", p.speed_rpm)
        self._set("speed_command", p.speed_command_rpm)
        self._set("torque_feedback", p.torque_pct)
        entry = self.profile.role("position_feedback")
        if entry is not None and entry.cls not in ("Pn", "Fn"):
            self.drive.bank.set_live(entry.code, p.position_counts, wrap=True)   # a multi-turn counter wraps
        self._set("following_error", p.following_error_counts)
        self._set("load_rate", p.load_rate_pct)
        self._set("current_rms", abs(p.torque_pct) / 100 * 2.8)
        self._set("bus_voltage", 311.0)
        self._set("alarm_code", self._alarm_code())
        for n, code in enumerate(self.alarm_history[:8], start=1):
            self._set(f"alarm_history_{n}", code)
        status = self.profile.role("servo_status")
        if status is not None:
            bits = {"servo_on": p.servo_on, "fault": p.alarm is not None, "moving": abs(p.true_speed_rpm) > 1,
                    "jog": self.mode == "jog", "identifying": self.mode == "ident"}
            where = {k: status_bit(status, k) for k in bits} if status.bits else STATUS_BITS
            word = sum(1 << b for k, on in bits.items() if on and (b := where.get(k)) is not None)
            self.drive.bank.set_live(status.code, word)


def _int(value: object, default: int) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else default


def _identification(raw: object, shift: float) -> Identification | None:
    """An Identification from its stored form, times moved into this process's clock; None when unusable."""
    if not isinstance(raw, dict):
        return None
    try:
        ident = Identification(**{f.name: raw[f.name] for f in fields(Identification) if f.name in raw})
        ident.phase_t0 = float(ident.phase_t0) + shift
        ident.estimates = [float(x) for x in ident.estimates or []]
    except (TypeError, ValueError):
        return None
    return ident


def build_drive(profile: Profile, unit: int, clock: Clock | None = None, *, persist: bool = True) -> SimulatedDrive:
    """A simulated drive with its firmware and plant attached."""
    drive = SimulatedDrive(profile, unit, persist=persist)
    drive.firmware = Firmware(drive, clock)  # type: ignore[attr-defined]
    return drive
