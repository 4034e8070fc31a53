"""Host-commanded motion with a dead-man: JOG through the profile's roles, keep-alive, limits, safe stop.

Two routes, chosen by role: a JOG trigger (role jog, speed from jog_speed; its raw values come from the entry's
enum names forward/reverse/stop, else +1/-1/0), or a signed speed reference with servo-on over communication
(roles speed_reference + servo_on).
"""

from __future__ import annotations

from collections.abc import Callable

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError
from servotool.model.codec import eng_to_raw, parse_value, raw_to_eng
from servotool.model.profile import Entry
from servotool.model.roles import FEATURE, jog_codes, motion_route
from servotool.motion import deadman, protect
from servotool.motion.deadman import DeadManBound
from servotool.motion.forced_inputs import ForcedInputs
from servotool.motion.jog_plan import JogPlan, checked_travel, ramp_words, travel_estimate
from servotool.motion.keepalive import KeepAlive, keepalive_interval_s
from servotool.motion.rest import STOPPED_RPM
from servotool.motion.segments import SegmentMoves
from servotool.motion.setup import check_setup
from servotool.motion.stop import MotionStop, StopReport
from servotool.motion.travel import TravelGuard, TravelLimit
from servotool.ops import alarms, journal
from servotool.ops.params import write_one
from servotool.ops.status import servo_is_on

KEY_POLL_S = 0.02  # interactive JOG polls the keys this often (key repeat comes about every 30 ms)


class Jogger:
    """JOG one drive with a keep-alive; every motion runs inside `stopping()`, which leaves the motor proven stopped.

    Motion commands (JOG trigger, speed reference, servo-on, keep-alive) are written as they are; the settings a
    motion changes (JOG speed, ramp) are parameters and go through ops.params.write_one.
    """

    def __init__(
        self, drive: Drive, keepalive_s: float = 0.1, feature: str = FEATURE, clock: Clock | None = None
    ) -> None:
        self.drive = drive
        self.profile = drive.profile
        self.feature = feature
        self.route = motion_route(self.profile, feature)
        check_setup(drive, feature)  # before anything is written: a drive not set up would ignore or misread us
        self.speed_entry = self.route.speed_entry
        self.jog = self.route.entries.get("jog")
        self.servo = self.route.entries.get("servo_on")
        self.speed_fb = self.profile.role("speed_feedback")
        self.clock = clock or RealClock()
        # Waits between beats; a trace (ops.trace.Sampler.sample_for) fills them with samples on the same link.
        self.idle: Callable[[float], None] = self.clock.sleep
        self.keepalive = KeepAlive(drive, keepalive_s, self.clock, resend=self._resend_command)
        self.direction = 0
        self.speed_rpm = 0.0
        self._enabled = False  # speed route: servo switched on by us
        self._ramp_raw: int | None = None
        self._speed_param_raw: int | None = None  # the speed parameter as this jogger last read or wrote it
        self._planned_ramp_raw: int | None = None  # the drive's ramp as plan() read it
        self.last_stop: StopReport | None = None  # what the last motion's stop read back
        self.dead_man: DeadManBound | None = None  # the bound of the fastest motion armed so far
        self.segments = SegmentMoves(drive, self.route, feature) if self.route.kind == "segment" else None
        self.guard = TravelGuard(drive, None)  # the soft travel limit of the planned JOG (none until plan())
        self._timeout_s: float | None = deadman.UNREAD  # the drive's communication timeout, read once
        # Called by every motion's stop scope (stopping(), motion/stop.py) before it moves, after the drive's own
        # protections are set (start_protection), with the settings to put back (code -> raw): a caller may write
        # temporary settings there, each original recorded in it first, and the stop puts them back with the
        # motion's own (tuning.stable_hold.guarded_jogger: a position hold that cannot swing up on an unknown load).
        self.prepare: Callable[[dict[str, int]], object] | None = None
        # The drive's own protections for the motion (motion/protect: planned by plan() or protect_for(), set with
        # the motion's settings and put back with them), and a forced-input trigger's forcing (SD25).
        self.protections: protect.Protections | None = None
        self._forcing_released = False  # command_zero released the forced inputs (release() proves it)
        self.inputs = (
            ForcedInputs(drive, self.clock, keepalive_s)
            if self.profile.forced_inputs is not None and self.route.kind == "trigger"
            else None
        )

    @property
    def keepalive_s(self) -> float:
        """The beat period."""
        return self.keepalive.interval_s

    def speed_limit(self) -> float:
        """The lowest of: the drive's max-speed parameter, the JOG speed range, the motor's max speed."""
        limits = [raw_to_eng(self.speed_entry, self.speed_entry.max)]
        max_speed = self.profile.role("max_speed")
        if max_speed is not None:
            limits.append(raw_to_eng(max_speed, self.drive.read_entries([max_speed])[0].raw))
        if self.profile.motor is not None:
            limits.append(self.profile.motor.max_speed_rpm)
        return float(min(limits))

    def plan(
        self,
        speed_rpm: float,
        seconds: float | None,
        max_travel_rev: float | None = None,
        travel: TravelLimit | None = None,
    ) -> JogPlan:
        """Check everything before any motion: alarm, servo state, speed and travel limits, the dead-man."""
        checked_travel(speed_rpm, seconds, max_travel_rev)
        limit = self.speed_limit()
        if abs(speed_rpm) > limit:
            raise UsageError(
                f"speed {abs(speed_rpm):g} rpm is over the limit {limit:g} rpm "
                "(drive max-speed parameter, JOG range, motor)"
            )
        parse_value(self.speed_entry, f"{abs(speed_rpm):g}")  # resolution and range of the speed entry
        if self._speed_raw(abs(speed_rpm)) == 0:
            raise UsageError(f"speed {abs(speed_rpm):g} rpm rounds to 0 in {self.speed_entry.code}: nothing would move")
        if self.profile.role("alarm_code") is not None:
            state = alarms.current(self.drive)
            if state.active:
                raise UsageError(
                    f"refusing to move: alarm {state.display} {state.name} is active "
                    "(see 'servotool alarm', clear it first)"
                )
        if self.servo_already_on():
            raise UsageError(
                "refusing to JOG: the servo is already on (enabled from elsewhere); switch it off first "
                "('servotool stop')"
            )
        if travel is not None:
            checked_travel(speed_rpm, seconds, travel.rev, travel.describe())
        self.guard = TravelGuard(self.drive, travel)
        self.keepalive.interval_s = min(self.keepalive_s, keepalive_interval_s(self.drive))
        accel_ms = self._ramp_ms()
        bound = self.arm_dead_man(abs(speed_rpm), accel_ms)
        if travel is not None:
            self._check_run_on(bound, abs(speed_rpm), seconds, accel_ms, travel)
        self.protect_for(abs(speed_rpm), self._fence_rev(speed_rpm, seconds, travel, accel_ms))
        bound = self.dead_man = self._protected(bound)
        return JogPlan(
            abs(speed_rpm),
            1 if speed_rpm > 0 else -1,
            seconds,
            limit,
            float(accel_ms) if accel_ms is not None else None,
            abs(speed_rpm) / 60.0 * seconds if seconds is not None else None,
            bound,
            travel,
            ramp_words(self.profile, float(accel_ms) if accel_ms is not None else None),
        )

    def _check_run_on(
        self, bound: DeadManBound, speed_rpm: float, seconds: float | None, accel_ms: float | None, travel: TravelLimit
    ) -> None:
        """The JOG's travel and what a dead host lets the motor run on beyond it must fit inside the travel limit
        (an interactive JOG: the run-on alone, the guard keeps that room ahead); else refused, naming the speed that
        fits, a shorter --time, more --travel or a shorter drive watchdog."""
        if not bound.bounded:
            return  # nothing bounds a dead host's run-on (--no-dead-man): the NO DEAD-MAN line says so
        assert bound.stop_rev is not None

        def need(speed: float) -> float:
            b = deadman.bound(self.drive, speed, self.keepalive.interval_s, accel_ms, timeout_s=self._timeout_s)
            return travel_estimate(speed, seconds) + (b.stop_rev or 0.0)

        if need(speed_rpm) <= travel.rev:
            return
        fits = deadman.largest_fitting_speed(speed_rpm, lambda v: need(v) <= travel.rev, 1.0)
        moved = f"travels about {travel_estimate(speed_rpm, seconds):.2f} rev and " if seconds is not None else ""
        remedy = f"--speed {fits:.0f} or lower" if fits is not None else "no speed does"
        raise UsageError(
            f"{travel.describe()}: a JOG at {speed_rpm:g} rpm {moved}could run on {bound.stop_rev:.2f} rev if this "
            f"program stopped ({bound.route}): {need(speed_rpm):.2f} rev in all; {remedy}"
            + (", a shorter --time" if seconds is not None else "")
            + f", more --travel{deadman.timeout_remedy(self.drive, bound)}"
        )

    def _fence_rev(
        self, speed_rpm: float, seconds: float | None, travel: TravelLimit | None, accel_ms: float | None
    ) -> float | None:
        """How far either way a JOG may go: its travel limit, else a timed JOG's travel, its stop and a beat."""
        if travel is not None:
            return travel.rev
        if seconds is None:
            return None  # an interactive JOG without a travel limit: no extent to fence
        speed = abs(speed_rpm)
        return (
            travel_estimate(speed, seconds)
            + deadman.braking_rev(speed, accel_ms, self.profile.ramp_rpm())
            + speed / 60.0 * self.keepalive.interval_s
        )

    def protect_for(self, peak_rpm: float, fence_rev: float | None) -> protect.Protections | None:
        """Plan the drive's protections for motion up to peak_rpm within fence_rev either way of where it starts
        (None: no fence); they are set when the motion starts (its stop scope: start_protection) and put back with
        its settings by the stop sequence. Not on an in-process link (no port: the benches' and seeded tests'
        virtual time), where their requests would only change which measurement noise the motion draws, and no
        journal exists to put them back."""
        if not self.drive.port:
            self.protections = None
            return None
        self.protections = protect.plan(self.drive, peak_rpm, fence_rev)
        if self.dead_man is not None:
            self.dead_man = self._protected(self.dead_man)
        return self.protections

    def _protected(self, bound: DeadManBound) -> DeadManBound:
        """The bound with what else bounds the motion: the protections planned, a forced-input warning."""
        return protect.limited(bound, self.protections, self.profile)

    def _ramp_ms(self) -> float | None:
        accel = self.profile.role("jog_accel")
        if accel is None:
            return None
        self._planned_ramp_raw = self.drive.read_entries([accel])[0].raw
        return float(raw_to_eng(accel, self._planned_ramp_raw))

    def arm_dead_man(self, speed_rpm: float, ramp_ms: float | None = None) -> DeadManBound:
        """The dead-man bound of motion up to speed_rpm (see motion/deadman); UsageError when it cannot be kept
        (no route without --no-dead-man, a link too slow for the beat). Every motion goes through here before it
        moves, the JOG's plan and each speed an identification or step check sets."""
        if self._timeout_s == deadman.UNREAD:
            self._timeout_s = deadman.drive_timeout_s(self.drive)
        bound = deadman.bound(
            self.drive,
            speed_rpm,
            self.keepalive.interval_s,
            ramp_ms if ramp_ms is not None else self._ramp_ms_now(),
            self.drive.dead_man_waived,
            self._timeout_s,
        )
        deadman.check(bound, self.drive.dead_man_waived)
        if self.protections is not None or self.inputs is not None:
            bound = self._protected(bound)
        if self.dead_man is None or bound.speed_rpm >= self.dead_man.speed_rpm:
            self.dead_man = bound
        return bound

    def servo_already_on(self) -> bool:
        """Servo on from elsewhere: the status word says so, or a servo-on held in a parameter is set."""
        return bool(servo_is_on(self.drive)) or (
            self.servo is not None
            and self.servo.readable
            and self.servo.cls == "Pn"
            and self.drive.read_entries([self.servo])[0].raw != 0
        )

    def _speed_raw(self, signed_rpm: float) -> int:
        return eng_to_raw(self.speed_entry, signed_rpm)

    def set_speed(self, speed_rpm: float) -> None:
        """The speed of the following moves (rpm, sign ignored); a running speed-route move changes at once."""
        self.speed_rpm = abs(speed_rpm)
        if self.dead_man is None or self.speed_rpm > self.dead_man.speed_rpm:
            self.arm_dead_man(self.speed_rpm)
        if self.route.kind in ("trigger", "segment"):
            raw = self._speed_raw(self.speed_rpm)
            if self.speed_param() != raw:  # no needless EEPROM write
                write_one(self.drive, self.speed_entry, raw)
                self._speed_param_raw = raw
            if self.route.kind == "segment" and self.direction:
                self._segment_command()  # the running move takes the new speed at once
        elif self._enabled and self.direction:
            self.drive.write_raw(self.speed_entry, self._speed_raw(self.direction * self.speed_rpm))

    def speed_param(self) -> int:
        """The speed parameter's raw value (trigger and segment routes): read once, then as this jogger wrote it."""
        if self._speed_param_raw is None:
            self._speed_param_raw = self.drive.read_entries([self.speed_entry])[0].raw
        return self._speed_param_raw

    def command(self, direction: int) -> None:
        """+1 forward, -1 reverse, 0 stop (ramped by the drive's JOG/speed accel time)."""
        self.direction = (direction > 0) - (direction < 0)
        if self.route.kind == "segment":
            self._segment_command()
            return
        if self.jog is not None:
            if self._forced_trigger_gone():
                return
            self.drive.write_raw(self.jog, self._trigger_raw())
            self.keepalive.sent()
            return
        assert self.servo is not None
        if self.direction and not self._enabled:
            # A reference held in a parameter (SDC's signed JOG speed PN22) would run at once on enable: zero it
            # first; the stop puts it back with the motion's other settings (_written_settings).
            self.drive.write_raw(self.speed_entry, self._speed_raw(0))
            self.drive.write_raw(self.servo, 1)
            self._enabled = True
        if self._enabled:
            self.drive.write_raw(self.speed_entry, self._speed_raw(self.direction * self.speed_rpm))
            self.keepalive.sent()

    def _trigger_raw(self) -> int:
        """The JOG trigger's raw value for the present direction (a forced-input trigger with the other inputs as
        held)."""
        assert self.jog is not None
        code = jog_codes(self.jog)[self.direction]
        return self.inputs.levels(code) if self.inputs is not None and self.inputs.engaged else code

    def _forced_trigger_gone(self) -> bool:
        """A forced-input trigger whose forcing is off (released by the stop): its forced value (put back as found)
        drives nothing, and is not written again."""
        return self.inputs is not None and not self.inputs.engaged and self._forcing_released

    def watch_inputs(self) -> None:
        """At most once a beat, where the drive's forced inputs can be watched: stop the motion on a wired input's
        change (motion.forced_inputs.InputsChanged)."""
        if self.inputs is not None:
            self.inputs.watch()

    def _segment_command(self) -> None:
        """The segment route: servo on for the first move, then a fresh move (or a braking one) now."""
        assert self.servo is not None
        if self.direction and not self._enabled and self.segments is not None:
            self.drive.write_raw(self.servo, 1)  # servo on, start bits off: the next write is an edge
            self.segments.start_high = False
            self._enabled = True
        if (
            self._enabled
            and self.segments is not None
            and self.segments.move(self.direction, self.speed_rpm, self.keepalive.interval_s, self._ramp_ms_now())
        ):
            self.keepalive.sent()

    def _ramp_ms_now(self) -> float | None:
        if self._ramp_raw is not None:
            return float(raw_to_eng(self._ramp_entry(), self._ramp_raw))
        return self._ramp_ms()

    def beat(self) -> None:
        """The dead-man keep-alive: without it the drive stops the motor after its timeout. On the segment route a
        fresh segment only once the running one has run its beats at speed and brakes by itself: a start edge earlier
        restarts it on one reading of the firmware, but brakes it (the falling edge) on the other, where a JOG
        re-armed every beat crawled (51 rpm peak for 300 on the simulator's strict reading). This way it runs at
        speed on the first, in whole segments on the second."""
        ka = self.keepalive
        if self.route.kind == "segment" and ka.entry is None:
            if self.direction and ka.due_after(deadman.SEGMENT_BEATS * ka.interval_s):
                ka.beat()
            return
        ka.beat()

    def _resend_command(self) -> None:
        """The beat of a drive without a keep-alive entry: the running command again (a segment route starts a
        fresh move from where the axis is)."""
        if self.route.kind == "segment":
            if self.direction:
                self._segment_command()
            return
        if self.jog is not None:
            if not self._forced_trigger_gone():
                self.drive.write_raw(self.jog, self._trigger_raw())
        elif self._enabled:
            # The reference again, never the servo-on: a servo switched off from elsewhere ('servotool stop') stays off.
            self.drive.write_raw(self.speed_entry, self._speed_raw(self.direction * self.speed_rpm))

    # ----- what the stop sequence (motion/stop.py) asks of a motion --------------------------------------------
    def start_protection(self, saved: dict[str, int]) -> None:
        """Inside the stop scope, before the motion moves (and before `prepare`): the heartbeat's lead (a watchdog
        relay closes, a main contactor's drive charges, before the first motion command), the planned protections
        set (their originals into `saved` and the journal first), the inputs forced (journaled first). What fails
        here still gets the stop, which puts back whatever was written."""
        self.keepalive.heartbeat_lead(self.idle)
        if self.protections is not None:
            protect.apply(self.drive, self.protections, saved)
        if self.inputs is not None:
            self.inputs.engage()

    def command_zero(self) -> float | None:
        """Zero speed, ramped by the drive (its wait: stop_wait_s). A forced-input trigger (SD25) drops its JOG
        bits and releases forcing at once, before the wait for rest: every input, the JOG's and a wired E-stop's,
        follows its terminal again while the motor ramps down (issue 29 item 6)."""
        self.command(0)
        if self.inputs is not None and self.inputs.engaged:
            self._forcing_released = True
            self.inputs.release()
        return None

    def keep_alive(self) -> None:
        """The drive's watchdog (and the heartbeat's relay) fed while it ramps down."""
        self.beat()

    def leave(self) -> None:
        """Servo off as found (servotool moves no drive whose servo is on): the drive stops holding the axis."""
        if self.servo is not None:
            self.drive.write_raw(self.servo, 0)
        self._enabled = False
        if self.segments is not None:
            self.segments.moving = 0

    def release(self) -> bool:
        """The motion has ended: the heartbeat (--heartbeat) stops (it fed a watchdog relay through the ramp-down),
        and forced inputs are released if command_zero could not, whatever the heartbeat did. True when this motion
        released forcing (the stop then proves it reads released)."""
        try:
            self.keepalive.stop_heartbeat()
        finally:
            forced = self._forcing_released or (self.inputs is not None and self.inputs.engaged)
            self._forcing_released = False
            if self.inputs is not None:
                self.inputs.release()  # where command_zero could not (a no-op once released)
        return forced

    def moving_rpm(self) -> float:
        """The fastest speed this jogger armed (its speed or its dead-man's): a swing after the stop within it is a
        loop ringing, not a runaway (motion.stop)."""
        return max(self.speed_rpm, self.dead_man.speed_rpm if self.dead_man is not None else 0.0)

    def stop_wait_s(self) -> float:
        """How long the stop waits for rest: twice the drive's ramp down from the fastest speed armed, and a second
        (the ramp as this jogger last read or wrote it: nothing is read here, the line may be gone)."""
        speed = self.moving_rpm()
        ramp_raw = self._ramp_raw if self._ramp_raw is not None else self._planned_ramp_raw
        entry = self.profile.role("jog_accel")
        ramp_ms = float(raw_to_eng(entry, ramp_raw)) if entry is not None and ramp_raw is not None else None
        return 1.0 + 2.0 * deadman.stop_time_s(speed, ramp_ms, self.profile.ramp_rpm())

    def starved(self, gap_s: float = 0.0) -> str:
        """Words for a drive watchdog alarm the host's stalls may have raised ("" here: a Mover, which learns its
        caller's stalls, says more; gap_s: a gap the caller saw itself)."""
        return ""

    def stopped(self, report: StopReport) -> None:
        """The stop sequence ran: what this jogger knew of the drive's state is gone; proven, the journal's record of
        the motion goes (its settings, dead processes' included, are back, and the servo is off)."""
        self.last_stop = report
        if report.confirmed and self.drive.port:
            journal.clear_motion(self.drive, servo_off=True)
        self.direction = 0
        self._enabled = False
        self._speed_param_raw = None
        if self.segments is not None:
            self.segments.moving = 0
            self.segments.forget_distance()  # the next move writes its displacement again

    def stopping(self, band_rpm: float = STOPPED_RPM, need_ramp: bool = False) -> MotionStop:
        """`with jogger.stopping() as saved:` around every motion: snapshot and journal of the settings it changes
        first (saved: code -> raw; add to it before writing one), the one stop sequence on every way out.
        band_rpm: the speed band of rest (a noisy speed reading's); need_ramp: the motion sets the ramp itself."""
        return MotionStop(self, band_rpm, need_ramp)

    def speed(self) -> float | None:
        if self.speed_fb is None:
            return None
        return float(raw_to_eng(self.speed_fb, self.drive.read_entries([self.speed_fb])[0].raw))

    def run(
        self,
        plan: JogPlan,
        on_sample: Callable[[float, float | None], None] | None = None,
        command: Callable[[], int | None] | None = None,
    ) -> None:
        """Run a planned JOG; `command` (interactive) returns a new direction (+1/-1/0) or None to quit.

        However it ends (its time, a key, Ctrl-C, a link error, the travel limit), the stop sequence stops the motor
        and proves it (motion/stop.py). The JOG's own writes stay out of EEPROM where the drive has a switch, and
        every parameter it writes is put back as it was found, so a JOG leaves no trace in the drive's settings.
        """
        with self.stopping():  # runs self.prepare first
            self._run(plan, on_sample, command)
        self.check_tripped()

    def _written_settings(self) -> list[Entry]:
        """The parameters this motion writes, to be put back as found: the JOG speed (or a speed reference held in
        a parameter, SDC PN22), a segment's displacement, and the ramp (role jog_accel), where the profile maps
        them."""
        entries = [self.speed_entry]
        if self.route.kind == "segment":
            entries.append(self.route.entries["segment_distance"])
        ramp = self.profile.role("jog_accel")
        if ramp is not None:
            entries.append(ramp)
        return [e for e in entries if e.readable and e.cls == "Pn"]

    def _snapshot(self) -> dict[str, int]:
        entries = self._written_settings()
        found = {e.code: r.raw for e, r in zip(entries, self.drive.read_entries(entries), strict=True)}
        return {**found, **journal.pending_settings(self.drive)}  # a dead process's originals win

    def _run(
        self,
        plan: JogPlan,
        on_sample: Callable[[float, float | None], None] | None = None,
        command: Callable[[], int | None] | None = None,
    ) -> None:
        self.set_speed(plan.speed_rpm)
        guard = self.guard
        guard.start()
        t0 = self.clock.now()
        self.command(plan.direction if command is None else 0)  # interactive: wait for the first key
        while True:
            elapsed = self.clock.now() - t0
            if plan.seconds is not None and elapsed >= plan.seconds:
                break
            if command is not None:
                new = command()
                if new is None:
                    break
                if new != self.direction:
                    self.command(new)
            if command is None or self.keepalive.due():  # interactive: keys are polled between beats
                self.beat()
                self.watch_inputs()
                self.check_tripped()
                # The room kept ahead: the stop's braking and a beat, and what a dead host lets it run on.
                braking = deadman.braking_rev(self.speed_rpm, plan.accel_ms, self.profile.ramp_rpm())
                run_on = plan.dead_man.stop_rev if plan.dead_man is not None else None
                guard.check(self.direction, max(braking + self.speed_rpm / 60.0 * self.keepalive_s, run_on or 0.0))
                if on_sample is not None:
                    on_sample(elapsed, self.speed())
            self.idle(self.keepalive_s if command is None else min(self.keepalive_s, KEY_POLL_S))

    def check_tripped(self) -> None:
        """A JOG the drive ended with an alarm is a failure, not a finished JOG."""
        state = alarms.confirmed(self.drive)
        if state is not None:
            raise DeviceError(
                f"the drive stopped the JOG with alarm {state.display} {state.name} (see 'servotool alarm')"
            )

    # ----- for motions that change the JOG settings (identification, step response) --------------------------
    def snapshot(self, need_ramp: bool = False) -> dict[str, int]:
        """Raw values (code -> raw) of the settings a motion changes and the stop puts back (see _written_settings),
        journaled before the motion (file writes do not delay its timing) for the next command should this one die,
        with the servo it may switch on (it refuses one already on). need_ramp: the motion sets the ramp (role
        jog_accel, then required)."""
        saved = self._snapshot()
        if need_ramp:
            self._ramp_raw = saved[self._ramp_entry().code]
        self._speed_param_raw = saved.get(self.speed_entry.code) if self.route.kind != "speed" else None
        if self.drive.port:
            journal.note_settings(self.drive, saved)
            if self.servo is not None:
                journal.note_servo(self.drive, self.servo.code)
        return saved

    def _ramp_entry(self) -> Entry:
        return self.profile.need_role("jog_accel", self.feature)

    def set_ramp(self, raw: int) -> None:
        """The JOG ramp time (role jog_accel, raw), written only when it changes."""
        if raw != self._ramp_raw:
            if self.speed_rpm:
                self.arm_dead_man(self.speed_rpm, float(raw_to_eng(self._ramp_entry(), raw)))
            write_one(self.drive, self._ramp_entry(), raw)
            self._ramp_raw = raw
