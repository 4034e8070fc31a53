"""The simulated drive's firmware: connects register writes/reads to the plant.

It runs only when a request arrives: the plant is integrated up to "now", with scheduled events (watchdog expiry,
identification phases) applied at their exact simulated times on the way. Roles, not vendor codes, say which
entry does what, so any profile with the roles gets the behaviour.

Servo on by command puts the drive in its control mode. Where the profile's motion route is a speed reference
(SDC), its motion_setup puts the drive in a speed mode (SDC's JOG mode), which has no position loop: standing still
is the speed loop holding zero speed (its integral keeps the position, softly). Elsewhere servo on is the plant's
position mode (DSX7E's Fn033; IS620P's segment route, H02-00 = 1 since issue 15): standing still holds position
through the position loop, so a load the motor cannot hold ends in the following-error alarm; a host speed reference
or a segment runs under speed control and the hold resumes where it returns to zero. That hold swings up whenever
the configured inertia ratio is far below the load (the position gain then exceeds the speed loop's real bandwidth),
as a real drive's would; servotool keeps its own motions' hold damped (tuning/stable_hold.py, issue 16).
JOG, a test function, runs under speed control throughout, its stop included, as real drives' JOG does (a position
hold there would also make a badly mis-tuned speed loop oscillate at every JOG stop of the inertia identification).

Around this core: `functions` decodes function writes into the actions below, `alarms` keeps the fault history,
`identification` runs the drive-side inertia identification, and `handover` keeps the running state in the state
file so the next process continues it (a power cycle starts it afresh).
"""

from __future__ import annotations

from servotool.clock import Clock, RealClock
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.forcing import trigger_bits
from servotool.model.gain_units import to_canonical
from servotool.model.profile import Entry, Motor, Profile
from servotool.model.roles import jog_direction
from servotool.model.setup import requirements
from servotool.sim import functions, monitors, protections
from servotool.sim.alarms import AlarmLog
from servotool.sim.device import SimulatedDrive
from servotool.sim.handover import Handover, MachineState
from servotool.sim.identification import Identification, Progress
from servotool.sim.loop_functions import FrictionFeedForward, GainSwitch, NotchSetting
from servotool.sim.mechanics import MechanicsSettings
from servotool.sim.plant import (
    BRAKE_HOLD_X_RATED,
    FOLLOWING_LIMIT_REV,
    DriveGains,
    Plant,
    PlantSettings,
)
from servotool.sim.segment import Segment

DEFAULT_MOTOR = Motor(source="servotool default: 400 W, 3000 rpm")
# A drive whose manual documents no communication timeout (no comm_timeout role) keeps running when the host dies,
# and so does the simulated one. Only `sim config --fake-watchdog on` (not real, off by default) makes it stop host
# motion, ramped and without an alarm, when no motion-role write arrives for this long.
FAKE_WATCHDOG_MS = 500.0
COUNT_UNITS = ("counts", "count", "pulse", "pulses", "p")
NOTCHES = 4  # notch roles notch1_* .. notch4_*
ADAPT_VIBRATION_PCT = 1.0  # the simulator's adaptive notch acts once the torque command vibrates this much
ADAPTIVE_NOTCH = 3  # the notch an adaptive notch takes (IS620P: notch 3 for one, 3 and 4 for two; unverified)
ADAPTED_WIDTH, ADAPTED_DEPTH = 2, 0  # and how it sets it
STOP_STEP_S = 0.01  # a quiet ramp-down after host loss is checked for standstill at this resolution


class Firmware:
    """Drive behaviour of one SimulatedDrive: JOG, speed command, servo on, watchdog, alarms, identification."""

    def __init__(self, drive: SimulatedDrive, clock: Clock | None = None) -> None:
        self.drive = drive
        self.profile: Profile = drive.profile
        self.clock = clock or RealClock()
        self.motor = self.profile.motor or DEFAULT_MOTOR
        self.alarms = AlarmLog(self.profile, drive.bank)
        self._setup = requirements(self.profile)
        self._handover = Handover(self.clock)
        self._power_on()
        self._take_machine_state()
        drive.on_read.append(lambda _d: self.update())
        drive.on_param_change.append(self._param_changed)
        drive.on_reload.append(self._reloaded)
        drive.bank.before_write.append(self._store_machine_state)
        functions.install(drive, self)
        self.plant.set_protections(self._protections())
        self.update()

    def _power_on(self) -> None:
        """The state right after power on: servo off, no alarm, position counter at zero, motor cold."""
        self.plant = Plant(self.motor, self._plant_settings(), self._gains(), start_time=self.clock.now())
        self.mode = "off"  # off | jog | speed | servo | ident | stopping (host lost, no alarm kind)
        self.jog_dir = 0
        self.last_host = self.clock.now()
        self.ident: Identification | None = None
        self.segment: Segment | None = None
        self._start_level = False
        self._queued = False  # a start edge came during a running segment: it starts once that one has settled
        self.alarms.recorded = False

    # ----- the running state, shared with other processes through the state file -----------------------------
    def _store_machine_state(self) -> None:
        self._handover.store(
            self.drive.bank.extra,
            MachineState(
                mode=self.mode,
                jog_dir=self.jog_dir,
                last_host=self.last_host,
                recorded=self.alarms.recorded,
                ident=self.ident,
                plant=self.plant.state(),
            ),
        )

    def _take_machine_state(self) -> None:
        """Continue from the running state another process stored (or start afresh after a power cycle)."""
        state = self._handover.take(self.drive.bank.extra)
        if state is None:
            return
        self._power_on()
        if state.plant is not None:
            self.plant.restore(state.plant, state.plant_shift)
        self.mode, self.jog_dir, self.ident = state.mode, state.jog_dir, state.ident
        if state.last_host is not None:
            self.last_host = state.last_host
        self.alarms.recorded = state.recorded
        if self.mode == "ident" and self.ident is None:
            self.mode = "off"
            self.plant.set_mode("off")
        if self.mode == "segment":  # a move is not handed over: it ends here, braking at the ramp
            self.plant.set_speed_command(0.0)
            self.mode = "servo"

    def _reloaded(self, _drive: SimulatedDrive) -> None:
        """Another process changed the drive's state (sim config, sim reset, another server): take it over."""
        self._take_machine_state()
        self.plant.set_settings(self._plant_settings())
        self.plant.set_gains(self._gains())
        self.plant.set_protections(self._protections())
        self.inputs_changed()  # the wired inputs may have changed (sim config), or forcing ended (power cycle)

    # ----- settings ------------------------------------------------------------------------------------------
    def _plant_settings(self) -> PlantSettings:
        s = self.drive.settings
        rated = self.motor.rated_torque_nm
        return PlantSettings(
            load_ratio=float(s["load_ratio"]),
            coulomb_nm=float(s["friction"]) * rated,
            viscous_nm_per_rad_s=float(s["viscous"]) * rated,
            load_torque_nm=float(s["load_torque"]) * rated,
            noise=float(s["noise"]),
            seed=int(s["seed"]),
            brake_nm=BRAKE_HOLD_X_RATED * rated if s["brake"] else 0.0,
            mechanics=MechanicsSettings.from_sim(s, rated),
        )

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
            torque_limit_pct=min(
                self._eng("torque_limit_fwd", 300.0),
                self._eng("torque_limit_rev", 300.0),
                self._eng("overload_multiple", 300.0),
            ),
            max_speed_rpm=min(self._eng("max_speed", self.motor.max_speed_rpm), self.motor.max_speed_rpm * 1.2),
            jog_accel_ms=max(1.0, self._eng("jog_accel", 200.0)) * self.motor.rated_speed_rpm / self.profile.ramp_rpm(),
            following_limit_rev=self._following_limit_rev(),
            notches=self._notches(),
            friction_ff=self._friction_ff(),
            gain_switch=self._gain_switch(),
        )

    def _gain_switch(self) -> GainSwitch:
        """The second gain set and its condition (roles gain_switch_mode, speed_loop_gain_2, speed_loop_integral_2,
        position_loop_gain_2, gain_switch_speed, gain_switch_delay), on the conditions the profile's mode entry
        names (its enum); a mode entry that names none (IS620P H08-09: the manual lists no conditions) is inert."""
        mode_e = self.profile.role("gain_switch_mode")
        if mode_e is None or self.profile.role("speed_loop_gain_2") is None:
            return GainSwitch()
        condition = mode_e.enum.get(self.drive.bank.effective_value(mode_e.code), "")
        return GainSwitch(
            condition=condition,
            speed_rpm=self._eng("gain_switch_speed", 10.0),
            delay_s=self._eng("gain_switch_delay", 100.0) / 1000.0,
            speed_gain_hz=self._gain("speed_loop_gain_2", 40.0),
            speed_integral_ms=self._eng("speed_loop_integral_2", 20.0),
            position_gain_per_s=self._gain_as("position_loop_gain_2", "position_loop_gain", 40.0),
        )

    def _gain_as(self, role: str, like: str, default: float) -> float:
        """A second-set gain in canonical units, read as its first-set role is (gain_units.to_canonical)."""
        entry = self.profile.role(role)
        return default if entry is None else to_canonical(like, entry, self._eng(role, default))

    def _notches(self) -> tuple[NotchSetting, ...]:
        """The torque-command notches the profile maps: roles notchN_freq, notchN_width and notchN_depth (% passed
        at the centre, IS620P's depth level) or notchN_attenuation (% cut there: how the simulator reads SD25's
        depth, whose sense its manual leaves open, so that its factory notches pass everything)."""
        found = []
        for n in range(1, NOTCHES + 1):
            if self.profile.role(f"notch{n}_freq") is None:
                continue
            if self.profile.role(f"notch{n}_depth") is not None:
                depth = self._eng(f"notch{n}_depth", 100.0)
            else:
                depth = 100.0 - self._eng(f"notch{n}_attenuation", 0.0)
            found.append(NotchSetting(self._eng(f"notch{n}_freq", 0.0), self._eng(f"notch{n}_width", 0.0), depth))
        return tuple(found)

    def _adapt_notch(self) -> None:
        """The drive's adaptive notch (role adaptive_notch: IS620P H09-02), a simulator extension: its manual names
        the modes, not how the drive finds a resonance. Modes 1 and 2 set notch ADAPTIVE_NOTCH at the machine's own
        resonance once the torque command vibrates (ADAPT_VIBRATION_PCT) with the servo on; mode 3 only reports it
        (role resonance_result); a machine without a resonance in the notch's range gets nothing."""
        entry = self.profile.role("adaptive_notch")
        if entry is None:
            return
        mode = self.drive.bank.effective_value(entry.code)
        hz = self.plant.settings.mechanics.resonance_hz
        freq = self.profile.role(f"notch{ADAPTIVE_NOTCH}_freq")
        self.plant.watch_vibration = mode in (1, 2, 3)
        if mode not in (1, 2, 3) or hz <= 0 or freq is None or not self.plant.servo_on:
            return
        if self.plant.vibration_pct < ADAPT_VIBRATION_PCT:
            return
        raw = eng_to_raw(freq, hz, clamp=False)
        if not freq.min <= raw <= freq.max:
            return
        wanted = {"freq": raw, "width": ADAPTED_WIDTH, "depth": ADAPTED_DEPTH}
        found = self.profile.role("resonance_result")
        changed = False
        if mode == 3:
            targets = [(found, raw)] if found is not None else []
        else:
            targets = [(self.profile.role(f"notch{ADAPTIVE_NOTCH}_{k}"), v) for k, v in wanted.items()]
        for target, value in targets:
            if target is not None and self.drive.bank.effective_value(target.code) != value:
                self.drive.bank.apply_parameter(target, value)
                changed = True
        if changed:
            self.plant.set_gains(self._gains())

    def _friction_ff(self) -> FrictionFeedForward:
        """The friction compensation the profile maps (roles torque_offset, friction_comp_fwd/_rev,
        viscous_comp_fwd/_rev), each in % of rated torque (an entry in another unit is not simulated)."""

        def pct(role: str) -> float:
            entry = self.profile.role(role)
            return self._eng(role, 0.0) if entry is not None and entry.unit == "%" else 0.0

        return FrictionFeedForward(
            pct("torque_offset"),
            pct("friction_comp_fwd"),
            pct("friction_comp_rev"),
            pct("viscous_comp_fwd"),
            pct("viscous_comp_rev"),
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

    def _param_changed(self, _drive: SimulatedDrive, _entry: Entry, _raw: int) -> None:
        self.update()
        self.plant.set_gains(self._gains())
        self.plant.set_protections(self._protections())

    def _protections(self) -> protections.Protections:
        return protections.protections(self.profile, self.drive.bank, self.motor, self.plant.position_rev)

    def reconfigure(self) -> None:
        """Apply changed simulated-machine settings (sim config): the machine, the wired inputs."""
        self.plant.set_settings(self._plant_settings())
        self.inputs_changed()

    @property
    def alarm_history(self) -> list[int]:
        """Latest first; kept in the state file like a drive's fault log."""
        return self.alarms.history

    # ----- time ----------------------------------------------------------------------------------------------
    def update(self) -> None:
        """Integrate the plant up to now, applying the watchdog and identification on the way; refresh monitors."""
        now = self.clock.now()
        if self._watched():
            expiry = self.last_host + self._eng("comm_timeout", FAKE_WATCHDOG_MS) / 1000.0
            if expiry < now:
                self.plant.advance_to(expiry)
                self._host_lost()
        if self.ident is not None:
            self._advance_identification(self.ident, now)
        if self.mode == "stopping":
            self._advance_stop(now)
        while self.mode == "segment" and self.segment is not None:
            if not self.segment.advance(self.plant, now, self._ramp_rev_s2()):
                break
            self.segment = None
            self.mode = "servo"  # the move ended: the drive holds there, servo on
            if self._queued:  # the start edge that came meanwhile (strict trigger semantics): it runs now
                self._queued = False
                self._start_segment()
        self.plant.advance_to(now)
        self._adapt_notch()
        if self.plant.alarm is not None:
            if self.mode != "off":
                self.mode = "off"
                self.ident = None
                self.segment = None
            self.alarms.record(self.plant.alarm, self._alarm_context())  # also alarms raised with the servo off
        self._refresh_monitors()

    def _watched(self) -> bool:
        """Whether a host watchdog runs: the profile's documented one (comm_timeout role) whenever the host holds
        the servo. A drive that documents none has none: only the labelled fake watchdog (sim config
        --fake-watchdog, off by default) stops host-commanded motion there."""
        if self.profile.role("comm_timeout") is not None:
            return self.mode in ("jog", "speed", "servo", "segment")
        return (
            bool(self.drive.settings["fake_watchdog"])
            and self.mode in ("jog", "speed", "segment")
            and (self.jog_dir != 0 or self.plant.target_rpm != 0.0)
        )

    def _host_lost(self) -> None:
        """The watchdog expired: a documented one stops with the profile's communication alarm; the fake one ramps
        down quietly (it has no alarm to show: the real drive has none)."""
        if self.profile.role("comm_timeout") is not None and self.profile.alarm_of_kind("comm_timeout") is not None:
            self.trip("comm_timeout")
            return
        servo = self.profile.role("servo_on")
        if servo is not None and servo.cls == "Pn":
            self.drive.bank.apply_parameter(servo, 0)  # a servo-on held in a parameter drops with the servo
            self.drive.bank.save()
        self.segment = None
        self.plant.set_speed_command(0.0)
        self.jog_dir = 0
        self.mode = "stopping"

    def _advance_stop(self, now: float) -> None:
        t = self.plant.time
        while self.mode == "stopping" and t < now:
            t = min(now, t + STOP_STEP_S)
            self.plant.advance_to(t)
            if abs(self.plant.true_speed_rpm) < 1.0:
                self.plant.set_mode("off")
                self.mode = "off"

    def trip(self, kind: str) -> None:
        """Latch an alarm of this kind as the drive's protection does: stop, servo off, enter the history."""
        self.plant.raise_alarm(kind)
        self.mode = "off"
        self.ident = None
        self.alarms.record(self.plant.alarm, self._alarm_context())

    # ----- actions (what the drive's functions trigger; see servotool.sim.functions) -------------------------
    def _host_alive(self) -> None:
        self.last_host = self.clock.now()

    def _ready_for_host_motion(self) -> bool:
        """No alarm and the profile's motion_setup in effect: without the setup a real drive ignores (or does
        something else with) a host JOG or servo-on, so the simulated one does not move either."""
        return self.plant.alarm is None and all(
            r.met(self.drive.bank.effective_value(r.entry.code)) for r in self._setup
        )

    def keep_alive(self) -> None:
        self.update()
        self._host_alive()

    def jog(self, direction: int) -> None:
        """JOG in a direction (+1/-1) at the JOG speed, or stop it (0)."""
        self.keep_alive()
        if direction == 0:
            if self.mode == "jog":  # stop, but stay excited (holding) until JOG is left with servo off
                self.plant.set_speed_command(0.0)
                self.jog_dir = 0
                if self.profile.role("servo_on") is None:
                    self.mode = "stopping"  # nothing to leave JOG with: the drive switches off once at rest
            return
        if self.plant.alarm is not None or self.mode not in ("off", "jog", "stopping"):
            return
        if self.mode != "jog" and not self._ready_for_host_motion():
            return
        if self.mode == "off":
            self.plant.set_mode("speed")
        self.mode = "jog"
        self.jog_dir = direction
        self.plant.set_speed_command(direction * self._eng("jog_speed", 100.0))

    def inputs_changed(self) -> None:
        """The digital input levels changed (forced value, forcing switch, wired terminals): a JOG trigger among them
        (role jog's bits, the JOGU/JOGD functions of a forced-input drive) starts or stops the JOG."""
        jog = self.profile.role("jog")
        if self.profile.forced_inputs is None or jog is None:
            return
        levels = protections.input_levels(self.profile, self.drive.bank, int(self.drive.settings["inputs"]))
        self.jog(jog_direction(jog, levels & trigger_bits(self.profile)))

    def _ramp_rev_s2(self) -> float:
        """The drive's ramp (role jog_accel: time from 0 to rated speed) in rev/s^2, as the plant runs it."""
        return self.motor.rated_speed_rpm / 60.0 / max(self.plant.gains.jog_accel_ms / 1000.0, 1e-3)

    def segment_start(self, level: bool) -> None:
        """The segment start input (IS620P PosInSen on a VDI): a rising edge with the servo on starts segment 1
        from here. During a running segment (unverified, not in the manual; issue 29 cites a third-party account of
        Inovance firmware): a rising edge is queued until the segment ends and settles, a falling edge brakes it.
        `sim config --segment-restart on` takes the older reading for comparison: a rising edge restarts segment 1
        at once from the present position, a falling edge does nothing."""
        self.keep_alive()
        rising, falling = level and not self._start_level, self._start_level and not level
        self._start_level = level
        if self.mode not in ("servo", "segment") or self.plant.alarm is not None:
            return
        running = self.mode == "segment" and self.segment is not None
        if running and not self.drive.settings["segment_restart"]:
            if falling and self.segment is not None:
                self.segment.brake(self.plant)
                self._queued = False  # the level went away before the queued start could act
            elif rising:
                self._queued = True
            return
        if rising:
            self._start_segment()

    def _start_segment(self) -> None:
        """Segment 1 from here, with the parameters now in effect."""
        per_rev = self._eng("segment_units_per_rev", 0.0) or float(self.motor.counts_per_rev)
        distance = self._eng("segment_distance", 0.0) / per_rev
        self.segment = Segment.start(self.plant, distance, self._eng("segment_speed", 0.0))
        self.mode = "segment"

    def command_speed(self, rpm: float) -> None:
        """A host speed reference: acts while the servo is on by command."""
        self.keep_alive()
        if self.mode in ("servo", "speed"):
            self.mode = "speed"
            self.plant.set_speed_command(rpm)

    def servo(self, on: bool) -> None:
        self.keep_alive()
        if on and self.mode == "off" and self._ready_for_host_motion():
            self.plant.set_mode(self._servo_mode())
            self.plant.set_speed_command(0.0)
            self.mode = "servo"
        elif not on and self.mode in ("servo", "speed", "jog", "stopping", "segment"):
            self.plant.set_mode("off")
            self.mode = "off"
            self.segment = None
            self._queued = False

    def reset_alarm(self) -> None:
        """Clear the latched alarm if its cause is gone; one that stays latched is not entered again."""
        self.update()
        self.plant.clear_alarms()
        self.alarms.recorded = self.plant.alarm is not None
        self._refresh_monitors()

    def reboot(self) -> None:
        """A soft reset: the running state starts afresh with the parameters now in effect."""
        self._power_on()

    def _servo_mode(self) -> str:
        """The plant mode of servo on by command: speed control where the route is a speed reference (the
        motion_setup's speed mode), the position loop's hold otherwise."""
        speed_route = self.profile.role("speed_reference") is not None and self.profile.role("jog") is None
        return "speed" if speed_route else "position"

    def identify(self, start: bool) -> None:
        """Start the drive-side inertia identification (from standstill, servo off), or abort it."""
        self.update()
        if not start:
            if self.ident is not None:
                self.ident = None
                self.plant.set_mode("off")
                self.mode = "off"
            return
        if self.plant.alarm is not None or self.mode != "off":
            return
        self.ident = Identification.start(
            self.plant,
            self._eng("inertia_id_torque", 50.0),
            self._eng("inertia_id_travel", 2.0),
            self.motor.rated_speed_rpm,
            self.clock.now(),
        )
        self.mode = "ident"

    def _advance_identification(self, ident: Identification, now: float) -> None:
        progress = ident.advance(self.plant, now)
        if progress is Progress.FAILED:
            self.trip("inertia_id_failed")
        elif progress is Progress.DONE:
            self._finish_identification(ident)

    def _finish_identification(self, ident: Identification) -> None:
        """The measured load ratio goes into the drive's inertia-ratio parameter."""
        self.plant.set_mode("off")
        self.mode = "off"
        self.ident = None
        ratio = ident.load_ratio(self.motor.rotor_inertia_kgcm2)
        if ratio is None:
            self.trip("inertia_id_failed")
            return
        entry = self.profile.role("inertia_ratio")
        if entry is None:
            return
        raw = eng_to_raw(entry, self.profile.param_from_load_ratio(max(0.0, ratio)))
        self.drive.bank.apply_parameter(entry, raw)
        self.plant.set_gains(self._gains())
        self.drive.bank.save()

    def _alarm_context(self) -> dict[str, float]:
        """What the drive records beside an alarm now; its run time counts from the simulated drive's first start."""
        started = self.drive.bank.extra.setdefault("first_start", self.clock.now())
        return monitors.alarm_context(self.profile, self.drive.bank, self.plant, self.clock.now() - started)

    def _refresh_monitors(self) -> None:
        monitors.refresh(
            self.profile,
            self.drive.bank,
            self.plant,
            self.alarms,
            jogging=self.mode == "jog",
            identifying=self.mode == "ident",
        )
        monitors.refresh_inputs(
            self.profile,
            self.drive.bank,
            protections.input_monitor(
                self.profile,
                self.drive.bank,
                int(self.drive.settings["inputs"]),
                bool(self.drive.settings["di_monitor"]),
            ),
            protections.encoder_position(self.motor, self.plant.position_rev),
        )


def build_drive(profile: Profile, unit: int, clock: Clock | None = None, *, persist: bool = True) -> SimulatedDrive:
    """A simulated drive with its firmware and plant attached."""
    drive = SimulatedDrive(profile, unit, persist=persist)
    drive.firmware = Firmware(drive, clock)  # type: ignore[attr-defined]
    return drive
