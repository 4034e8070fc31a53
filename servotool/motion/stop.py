"""The one stop sequence of every motion servotool commands, and what it proves.

However a motion ends (it finished, Ctrl-C, SIGTERM, SIGHUP, a lost line, any exception, a failed check), the
same sequence runs, with every further interrupt held until it is done: command zero speed (a drive whose inputs
the motion forced, SD25, has forcing released with it: its wired E-stop acts again while the motor ramps down),
wait for rest, put the servo back as found, stop the heartbeat (--heartbeat: it fed a watchdog relay through the
ramp), write back every parameter the motion wrote (its speed and ramp, a softer hold, the drive-side protections of
motion/protect), then READ THE DRIVE BACK. It returns facts (StopReport: the speed read, the servo state read, the
settings verified); the CLI words them in its last line, and where they could not be proven it says so in capitals
and exits 4 (StopUnconfirmed). `servotool stop` runs the same sequence on a drive it knows nothing about (DriveHalt).

Interrupts are held while it runs (motion/interrupts.py).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from typing import Protocol

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError, StopUnconfirmed
from servotool.model.codec import format_value, raw_to_eng
from servotool.model.forcing import is_forcing, switch_value
from servotool.model.profile import Entry
from servotool.model.quantity import quantity
from servotool.motion.interrupts import GUARD, held_interrupts
from servotool.motion.rest import SETTLE_S, STOPPED_RPM, RestWatch
from servotool.ops import alarms
from servotool.ops.status import servo_is_on

PROOF_BAND_RPM = 10.0  # proven at rest: each speed reading under this at least (a noisy one's band is wider), RestWatch
DEFAULT_WAIT_S = 3.0  # the stop's wait for rest where the motion's own cannot be worked out
# A read's failure that shows the line answering (replies that did not agree with their confirming read: a live
# value, or stray replies), as opposed to a silent or lost line: a stop waits on through it.
LINE_ANSWERS = ("unsettled", "disagree")
RUNAWAY_SHARE = 1.2  # waiting for rest, a speed this much above the first one read, and above the motion's own speed
#                       where known, means the drive is not stopping it


# ----- the facts ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class StopReport:
    """What the stop sequence read back from the drive (facts; `describe` words them)."""

    speed_rpm: float | None  # the last speed read; None: no speed monitor, or no answer
    at_rest: bool | None  # the speed stayed inside the band, its mean near zero (RestWatch); None: no speed monitor
    servo_on: bool | None  # read back; None: the drive shows no servo state
    servo_found_on: bool  # before the motion (servotool moves only a drive whose servo is off)
    servo_entry: str  # what the servo state was read from
    settings: tuple[str, ...]  # the parameters the motion wrote, each checked against its original
    settings_back: bool  # every one reads back as it was found
    forcing: str = ""  # forced inputs as read back ("So-58 released"), "" where the drive forces none
    alarm: str = ""  # an alarm the drive shows now ("E25 host watchdog"): it stopped, and says why
    problems: tuple[str, ...] = ()  # what could not be done or proven
    band_rpm: float = PROOF_BAND_RPM  # |speed| under this counts as at rest (a noisy speed reading widens it)
    moved: bool = True  # False: an interrupt came before any motion of the command (read back only, nothing written)

    @property
    def confirmed(self) -> bool:
        return not self.problems

    def describe(self) -> str:
        """The last line of a command that moved: what the drive was read to be."""
        if not self.confirmed:
            return (
                "COULD NOT CONFIRM THE MOTOR STOPPED: "
                + "; ".join(self.problems)
                + " (stop it at the drive, or with 'servotool stop' once the line answers)"
            )
        servo = "servo on (as found)" if self.servo_found_on else "servo off"
        noisy = f" (inside its ±{self.band_rpm:.0f} rpm speed noise)" if self.band_rpm > PROOF_BAND_RPM else ""
        read = [f"{self.speed_rpm:g} rpm{noisy}" if self.speed_rpm is not None else "no speed monitor"]
        read.append(
            f"{self.servo_entry} {'on' if self.servo_on else 'off'}"
            if self.servo_on is not None
            else "no servo state shown"
        )
        if self.settings:
            read.append(f"{len(self.settings)} setting(s) as found")
        if self.forcing:
            read.append(self.forcing)
        if self.alarm:
            read.append(f"alarm {self.alarm} latched (see 'servotool alarm')")
        if not self.moved:
            return f"nothing moved: {'at rest, ' if self.at_rest else ''}{servo} (read back: {', '.join(read)})"
        return f"stopped, {servo} (read back: {', '.join(read)})"

    def as_json(self) -> dict[str, object]:
        return {
            "confirmed": self.confirmed,
            "moved": self.moved,
            "speed": quantity(None if self.speed_rpm is None else round(self.speed_rpm, 1), "rpm"),
            "at_rest": self.at_rest,
            "servo_on": self.servo_on,
            "servo_as_found": self.servo_on is None or self.servo_on == self.servo_found_on,
            "settings_restored": list(self.settings),
            "settings_verified": self.settings_back,
            "forcing": self.forcing or None,
            "alarm": self.alarm or None,
            "problems": list(self.problems),
            "message": self.describe(),
        }


_REPORTS: list[StopReport] = []


def reports() -> list[StopReport]:
    """Every stop this process made, in order (the CLI words the last, or the first it could not prove)."""
    return list(_REPORTS)


def final(found: list[StopReport] | None = None) -> StopReport | None:
    """The report the command's last line gives: the first unconfirmed one, else the last."""
    found = reports() if found is None else found
    return next((r for r in found if not r.confirmed), found[-1] if found else None)


# ----- what a motion offers its stop ----------------------------------------------------------------------------


class Halt(Protocol):
    """The motion-specific steps of the stop sequence (Jogger; DriveHalt for `servotool stop`)."""

    def command_zero(self) -> float | None:
        """Command zero speed (ramped by the drive), and release forced inputs (profile forced_inputs) with it.
        Returns how long the drive may take to come to rest from it (0: nothing was commanded, the servo-off stops
        the motor), None: the sequence's wait_s."""

    def keep_alive(self) -> None:
        """Keep the drive's watchdog fed while it ramps down."""

    def leave(self) -> None:
        """Servo back as found (off)."""

    def release(self) -> bool:
        """The motion's end for what else holds the drive: the heartbeat (--heartbeat) stopped, forced inputs
        released where command_zero could not. True when the motion released forcing, which the stop then proves
        reads released."""


def servo_state(drive: Drive) -> tuple[bool | None, str]:
    """(servo on, what it was read from): the status bit where the profile has one, else the servo-on entry
    (IS620P H31-00 bit 0, SDC PN95); (None, "") where the drive shows neither."""
    on = servo_is_on(drive)
    status = drive.profile.role("servo_status")
    if on is not None and status is not None:
        return on, status.code
    servo = drive.profile.role("servo_on")
    if servo is None or not servo.readable:
        return None, ""
    raw = drive.read_entries([servo])[0].raw
    dead_man = drive.profile.dead_man
    start = dead_man.start_value if dead_man is not None and dead_man.route == "segment" else 0
    return bool(raw & ~start), servo.code


def forcing_switch(drive: Drive) -> Entry | None:
    """The drive's forcing switch (profile forced_inputs: SD25 So-58), where host motion forces its inputs."""
    spec = drive.profile.forced_inputs
    return drive.profile.entry(spec.switch_code) if spec is not None else None


def release_forcing(drive: Drive) -> None:
    """Forcing off (model.forcing.switch_value: the switch's other digits kept), so that the drive's wired inputs,
    E-stop and limits, act again: what `servotool stop` asks of a drive it knows nothing about (a motion releases
    its own forcing, motion.forced_inputs.ForcedInputs.release, and the journal a dead process's)."""
    entry = forcing_switch(drive)
    if entry is None:
        return
    raw = drive.read_entries([entry])[0].raw
    if is_forcing(drive.profile, raw):
        drive.write_raw(entry, switch_value(drive.profile, raw, False))


def forcing_state(drive: Drive) -> tuple[bool | None, str]:
    """(forcing on, in words) as read now; (None, "") where the drive forces no inputs."""
    entry = forcing_switch(drive)
    if entry is None:
        return None, ""
    on = is_forcing(drive.profile, drive.read_entries([entry])[0].raw)
    return on, (f"{entry.code} forcing on: wired inputs ignored" if on else f"{entry.code} released")


# ----- the sequence --------------------------------------------------------------------------------------------


@dataclass
class _Steps:
    """The sequence's bookkeeping: what failed, and whether the line still answers."""

    problems: list[str] = field(default_factory=list)
    line_dead: bool = False

    def run(self, what: str, step: Callable[[], object], tries: int = 1) -> bool:
        """Run one step (up to `tries` times on a line fault, once the line stops answering); a failure is noted
        and the sequence goes on, whatever it was: a fault in one step (a bug included) must not keep the next,
        the servo-off, from being sent."""
        failure: Exception | None = None
        for _ in range(1 if self.line_dead else tries):
            try:
                step()
                return True
            except DeviceError as exc:
                failure = exc
            except ServoError as exc:
                failure = exc
                break
            except Exception as exc:  # an internal error, said as one: the stop goes on
                self.problems.append(f"{what} failed (internal error: {type(exc).__name__}: {exc})")
                return False
        self.problems.append(f"{what} failed ({failure})")
        if isinstance(failure, DeviceError) and (failure.fault == "silent" or "link lost" in str(failure)):
            self.line_dead = True
        return False


def _wait_for_rest(
    drive: Drive,
    halt: Halt,
    steps: _Steps,
    wait_s: float,
    band_rpm: float,
    clock: Clock,
    idle: Callable[[float], None],
    poll_s: float,
    moving_rpm: float | None = None,
) -> tuple[bool | None, float | None]:
    """Wait (bounded) until the speed stays inside the band (RestWatch): (at rest, the last speed); at rest None
    where the drive shows no speed. A motor that speeds up instead (a load the drive cannot hold) ends the wait at
    once: the servo-off comes next. Speeding up is judged against the first speed read and the motion's own
    (moving_rpm, where known): a loop that rings after the stop swings within the speed it moved at, and the first
    reading may catch it near zero (a load of 50 on a gravity axis, read at 62 rpm, then 89 on its swing: called a
    runaway, the servo went off at 104 rpm and the load fell 3.6 rev before its brake closed)."""
    watch, speed, end = RestWatch(band_rpm), None, clock.now() + wait_s
    first: float | None = None
    while not steps.line_dead:
        try:
            speed = _speed(drive)
        except DeviceError as exc:
            if exc.fault not in LINE_ANSWERS:
                steps.problems.append(f"reading the speed failed ({exc})")
                steps.line_dead = True
                break
            # After an interrupted request the link confirms reads by a second that agrees, which a turning
            # motor's speed (or its noise at rest) need not: the line answers, so wait on (the read-back proves
            # rest or says why not).
            if clock.now() >= end:
                return False, speed
            steps.run("feeding the drive's watchdog", halt.keep_alive)
            if not steps.run("waiting", lambda: idle(poll_s)):  # a JOG's trace samples while it waits
                break
            continue
        except Exception as exc:  # the wait ends; the servo-off comes next all the same
            steps.problems.append(f"reading the speed failed ({type(exc).__name__}: {exc})")
            break
        if speed is None or watch.at_rest(clock.now(), speed):
            return (None if speed is None else True), speed
        first = abs(speed) if first is None else first
        if clock.now() >= end or abs(speed) > RUNAWAY_SHARE * max(first, moving_rpm or 0.0) + PROOF_BAND_RPM:
            return False, speed
        steps.run("feeding the drive's watchdog", halt.keep_alive)
        if not steps.run("waiting", lambda: idle(poll_s)):  # a JOG's trace samples while it waits
            break
    return False, speed


def _speed(drive: Drive) -> float | None:
    entry = drive.profile.role("speed_feedback")
    return float(raw_to_eng(entry, drive.read_entries([entry])[0].raw)) if entry is not None else None


@dataclass
class _Read:
    """The drive as the stop's last step read it (what a failed reading leaves as it was)."""

    speed_rpm: float | None = None
    at_rest: bool | None = None
    servo_on: bool | None = None
    servo_code: str = ""
    forcing_on: bool | None = None
    forcing: str = ""
    alarm: str = ""
    judgement: str = ""  # how the speed read fails rest: "not under 10 rpm", "mean of its last 10 readings, ..."
    readings: int = 0  # how many speed readings the judgement took


PROOF_SPARE_READINGS = 3  # the proof reads the speed at most this many times the readings its mean needs (and 4 more)


def _read_drive(
    drive: Drive,
    read: _Read,
    band: float,
    idle: Callable[[float], None],
    clock: Clock,
    servo_found_on: bool,
    servo_wait_s: float = 0.0,
) -> None:
    """The speed at rest (RestWatch over several readings, bounded), then the servo state, forced inputs and alarm,
    into `read`. A servo not yet as found is read again for up to servo_wait_s: a drive may switch it off only once
    at rest (SD25's JOG, released) or after its brake's delay."""
    speed_e = drive.profile.role("speed_feedback")
    if speed_e is not None:
        watch = RestWatch(band)
        last, peak, read.at_rest = 0.0, 0.0, False
        for count in range(1, PROOF_SPARE_READINGS * watch.readings_needed + 5):
            if count > 1:
                idle(SETTLE_S / 2)
            last, read.readings = float(_speed(drive) or 0.0), count
            peak = max(peak, abs(last))
            if watch.at_rest(clock.now(), last):
                read.at_rest = True
                break
        read.speed_rpm, read.judgement = last, f"not under {band:g} rpm"
        if read.at_rest:
            read.speed_rpm = round(watch.mean_rpm, 1)
        elif abs(last) < band <= peak:  # the last reading inside the band the others kept leaving
            read.judgement = f"readings up to {peak:g} rpm among {read.readings}, not staying under {band:g} rpm"
        elif abs(last) < band:  # every reading in the band: the mean was not near zero
            read.speed_rpm = round(watch.mean_rpm, 1)
            read.judgement = f"mean of its last {len(watch)} readings, not under {watch.mean_band_rpm:g} rpm"
    end = clock.now() + servo_wait_s
    read.servo_on, read.servo_code = servo_state(drive)
    while read.servo_on is not None and read.servo_on != servo_found_on and clock.now() < end:
        idle(SETTLE_S)
        read.servo_on, read.servo_code = servo_state(drive)
    read.forcing_on, read.forcing = forcing_state(drive)
    state = alarms.confirmed(drive)
    read.alarm = f"{state.display} {state.name}" if state is not None else ""


def _report(
    steps: _Steps,
    read: _Read,
    band: float,
    servo_found_on: bool,
    since: str,
    more: list[str] | None = None,
    settings: tuple[str, ...] = (),
    settings_back: bool = False,
    moved: bool = True,
) -> StopReport:
    """The facts, with what the drive read that proves no stop (since: when the speed should have been at rest)
    and the sequence's `more` problems."""
    if read.at_rest is False and read.speed_rpm is not None:
        judged = read.judgement or f"not under {band:g} rpm"
        steps.problems.append(f"the speed reads {read.speed_rpm:g} rpm ({judged}{since})")
    if read.servo_on is not None and read.servo_on != servo_found_on:
        steps.problems.append(f"{read.servo_code} reads the servo {'on' if read.servo_on else 'off'}")
    steps.problems += more or []
    return StopReport(
        read.speed_rpm,
        read.at_rest,
        read.servo_on,
        servo_found_on,
        read.servo_code,
        settings,
        settings_back,
        read.forcing,
        read.alarm,
        tuple(steps.problems),
        band,
        moved,
    )


def read_back(drive: Drive, *, moved: bool, clock: Clock | None = None) -> StopReport:
    """The stop sequence's last step alone, for an interrupt that no motion's stop answered (proven_on_interrupt:
    before the first motion of a command, between two): nothing of servotool's moves the drive or holds it then
    (each motion's stop has run, or none started), so nothing is written; the drive is read as the stop reads it.
    moved: a motion of the command ran (and its stop) before the interrupt."""
    clock = clock or RealClock()
    steps, read = _Steps(), _Read()
    steps.run(
        "reading the drive back", lambda: _read_drive(drive, read, PROOF_BAND_RPM, clock.sleep, clock, False), tries=2
    )
    return _report(steps, read, PROOF_BAND_RPM, False, "", moved=moved)


def stop_sequence(
    drive: Drive,
    halt: Halt,
    saved: dict[str, int],
    *,
    wait_s: float,
    band_rpm: float = STOPPED_RPM,
    servo_found_on: bool = False,
    clock: Clock | None = None,
    idle: Callable[[float], None] | None = None,
    poll_s: float = 0.02,
    moving_rpm: float | None = None,
) -> StopReport:
    """Zero speed, rest, servo as found, heartbeat stopped and forced inputs released, the motion's settings back,
    then the drive read back.

    saved: code -> raw of every parameter the motion wrote (written back where it differs, then all read back);
    wait_s: how long the drive may take to come to rest (its ramp from the motion's speed, with margin);
    band_rpm: the speed band of rest the servo-off waits for (the motion's: a ringing loop swings through zero);
    the proof takes PROOF_BAND_RPM at least; moving_rpm: the fastest the motion moved (None: unknown), within which
    a swing after the stop is no runaway (_wait_for_rest). Each step
    runs even when one before it failed (a servo-off stops a motor whose zero command was lost); once the line stops
    answering, each is tried once."""
    GUARD.armed = False
    clock = clock or RealClock()
    idle = idle or clock.sleep
    band = max(band_rpm, PROOF_BAND_RPM)
    steps = _Steps()
    ramp_s: list[float | None] = [None]

    def zero() -> None:
        ramp_s[0] = halt.command_zero()

    steps.run("commanding zero speed", zero, tries=2)
    first_wait = wait_s if ramp_s[0] is None else min(wait_s, ramp_s[0])
    at_rest, speed = _wait_for_rest(drive, halt, steps, first_wait, band_rpm, clock, idle, poll_s, moving_rpm)
    steps.run("switching the servo off", halt.leave)
    if at_rest is False:  # the servo-off stops it (the drive's own servo-off stop), or it coasts
        at_rest, speed = _wait_for_rest(drive, halt, steps, wait_s, band_rpm, clock, idle, poll_s)
    released = [False]

    def release() -> None:
        released[0] = halt.release()

    steps.run("stopping the heartbeat and releasing the forced inputs", release)
    entries = [drive.profile.entry(code) for code in saved]
    back = False

    def put_back_settings() -> None:
        nonlocal back
        readings = drive.read_entries(entries)
        for entry, reading in zip(entries, readings, strict=True):
            if reading.raw != saved[entry.code]:
                drive.write_raw(entry, saved[entry.code])
        now = drive.read_entries(entries)
        differ = [
            f"{e.code} {format_value(e, r.raw)}" for e, r in zip(entries, now, strict=True) if r.raw != saved[e.code]
        ]
        if differ:
            raise DeviceError(f"read back {', '.join(differ)}")
        back = True

    if entries:
        steps.run(f"putting back {len(entries)} setting(s)", put_back_settings)
    read = _Read(speed, at_rest)
    steps.run(
        "reading the drive back",
        lambda: _read_drive(drive, read, band, idle, clock, servo_found_on, wait_s),
        tries=2,
    )
    more = []
    if released[0] and read.forcing_on:
        more.append(f"{read.forcing} (the release did not take)")
    if entries and not back and not any("setting" in p for p in steps.problems):
        more.append("the motion's settings could not be put back")
    codes = tuple(e.code for e in entries)
    return _report(steps, read, band, servo_found_on, f" {wait_s:.1f} s after the stop", more, codes, back)


# ----- a motion's life: from its snapshot to its proven stop ---------------------------------------------------


class Motion(Protocol):
    """What MotionStop needs of the motion (Jogger)."""

    drive: Drive
    clock: Clock

    def command_zero(self) -> None: ...
    def keep_alive(self) -> None: ...
    def leave(self) -> None: ...
    def release(self) -> bool: ...
    def start_protection(self, saved: dict[str, int]) -> None: ...
    def snapshot(self, need_ramp: bool) -> dict[str, int]: ...
    def stop_wait_s(self) -> float: ...
    def moving_rpm(self) -> float | None: ...
    def starved(self) -> str: ...
    def stopped(self, report: StopReport) -> None: ...


class MotionStop:
    """`with MotionStop(jogger) as saved:` — the motion's own protections (start_protection: the heartbeat's lead,
    the drive-side protections planned, forced inputs engaged) and its `prepare` hook (if any: temporary settings
    such as a softer hold), each original recorded in saved before it is written, run first; then the motion runs
    inside; however it leaves, the stop sequence runs
    with interrupts held, inside the drive's RAM-only writes (ops.eeprom.ram_writes), and its report is recorded
    (and attached to the exception that ended it, as `stop_report`). A normal end whose stop is not proven raises
    StopUnconfirmed, one whose read-back shows an alarm DeviceError (the motion started without one, so the drive
    tripped during it: not a success); an interrupt held during the stop is raised after it."""

    def __init__(self, motion: Motion, band_rpm: float = STOPPED_RPM, need_ramp: bool = False) -> None:
        self.motion, self.band_rpm, self.need_ramp = motion, band_rpm, need_ramp
        self.saved: dict[str, int] = {}
        self._stack = ExitStack()

    def __enter__(self) -> dict[str, int]:
        from servotool.ops.eeprom import ram_writes

        GUARD.enter()
        try:  # nothing is written before the snapshot: a failure here leaves nothing to stop
            self._stack.enter_context(ram_writes(self.motion.drive))  # the port's lock, then the EEPROM switch
            # The snapshot journals what it read: an interrupt waits for its end, then gets the stop (which clears
            # the record): no record of a motion that no stop followed.
            with held_interrupts():
                self.saved = self.motion.snapshot(self.need_ramp)
        except BaseException as exc:
            if isinstance(exc, KeyboardInterrupt) and self.saved:
                self._finish(exc)
                raise
            try:
                self._stack.close()
            finally:
                GUARD.leave()
            raise
        prepare = getattr(self.motion, "prepare", None)
        try:  # temporary settings for the motion's duration, each original added to saved (and journaled) first
            self.motion.start_protection(self.saved)
            if prepare is not None:
                prepare(self.saved)
        except BaseException as exc:
            self._finish(exc)
            raise
        return self.saved

    def __exit__(self, _kind: object, exc: BaseException | None, _tb: object) -> bool:
        GUARD.armed = False
        self._finish(exc)
        return False

    def _finish(self, exc: BaseException | None) -> None:
        GUARD.armed = False
        motion = self.motion
        closing: ServoError | None = None  # putting the drive's EEPROM switch back failed (ops.eeprom.ram_writes)
        try:
            try:
                wait_s = motion.stop_wait_s()
            except ServoError:
                wait_s = DEFAULT_WAIT_S
            report = stop_sequence(
                motion.drive,
                motion,
                self.saved,
                wait_s=wait_s,
                band_rpm=self.band_rpm,
                clock=motion.clock,
                idle=getattr(motion, "idle", None),  # a JOG's trace keeps sampling while it stops
                moving_rpm=motion.moving_rpm(),
            )
        finally:
            try:
                self._stack.close()
            except ServoError as failure:
                closing = failure
            finally:
                held = GUARD.leave()
        _REPORTS.append(report)
        motion.stopped(report)
        if exc is not None:
            exc.stop_report = report  # type: ignore[attr-defined]
            if closing is not None:
                exc.add_note(f"after the stop: {closing}")
            if held and not isinstance(exc, KeyboardInterrupt):
                # Ctrl-C came while a failure's stop ran: the command ends as interrupted, not on with the failure
                raise _interrupt_after(exc, report) from exc
            return
        if closing is not None:
            closing.stop_report = report  # type: ignore[attr-defined]
            raise closing
        if held:
            interrupt = GUARD.interrupt()
            interrupt.stop_report = report  # type: ignore[attr-defined]
            raise interrupt
        if not report.confirmed:
            raise StopUnconfirmed(report.describe(), report)
        if report.alarm:  # a motion starts only without one (preflight): the drive tripped during it
            tripped = DeviceError(
                f"the drive latched alarm {report.alarm} during the motion{motion.starved()} (see 'servotool alarm')"
            )
            tripped.stop_report = report  # type: ignore[attr-defined]
            raise tripped


GUARD.protected.update({MotionStop.__exit__.__code__, MotionStop._finish.__code__, stop_sequence.__code__})


@contextmanager
def proven_on_interrupt(drive: Drive, clock: Clock | None = None) -> Iterator[None]:
    """`with proven_on_interrupt(drive):` around a motion command, from before it says its bound to its end: the
    first interrupt raises as ever, later ones are held (motion/interrupts), and an interrupt that no motion's stop
    answered (before the first motion: its plan lines, pre-motion reads, a prompt; between two motions) ends with
    the drive read back (read_back: 'nothing moved: at rest, servo off', or the stopped line after a motion), its
    report recorded and attached to the exception as a motion's stop attaches its own. What was written before the
    interrupt is put back by its owner on the way out (a motion's stop, the EEPROM switch, a gain rollback)."""
    since = len(_REPORTS)
    GUARD.enter()
    try:
        yield
    except BaseException as exc:
        # A prompt turns the interrupt into its own exception (click's Abort), whose context is the interrupt.
        interrupted = isinstance(exc, KeyboardInterrupt) or isinstance(exc.__context__, KeyboardInterrupt)
        held = GUARD.held > 0  # one held on the failure's way out (a stop, a rollback): the command is interrupted
        if (interrupted or held) and getattr(exc, "stop_report", None) is None:
            GUARD.armed = False
            report = read_back(drive, moved=len(_REPORTS) > since, clock=clock)
            _REPORTS.append(report)
            exc.stop_report = report  # type: ignore[attr-defined]
        if held and not interrupted:
            raise _interrupt_after(exc, exc.stop_report) from exc  # type: ignore[attr-defined]
        raise
    finally:
        GUARD.leave()


def _interrupt_after(failure: BaseException, report: StopReport) -> KeyboardInterrupt:
    """The interrupt held while a failure was on its way out, which it replaces (the failure said in a note)."""
    interrupt = GUARD.interrupt()
    interrupt.stop_report = report  # type: ignore[attr-defined]
    interrupt.add_note(f"it came as the command failed: {failure}")
    for note in getattr(failure, "__notes__", ()):
        interrupt.add_note(note)
    return interrupt


GUARD.protected.add(proven_on_interrupt.__wrapped__.__code__)


# ----- `servotool stop` ----------------------------------------------------------------------------------------


class StoppedElsewhere(DeviceError):
    """The servo a motion switched on reads off: something else stopped the drive ('servotool stop')."""


class DriveHalt:
    """The stop of a drive servotool knows nothing about (`servotool stop`): every motion role the profile maps is
    commanded to zero (a JOG trigger, a communication speed reference, the drive's own identification) and forced
    inputs are released (profile forced_inputs), then the servo goes off; nothing is read first that could fail
    before the first write."""

    def __init__(self, drive: Drive) -> None:
        self.drive = drive
        p = drive.profile
        self.jog = p.role("jog")
        self.reference = p.role("speed_reference")
        self.servo = p.role("servo_on")
        self.keepalive = p.role("keepalive")
        ident = p.role("inertia_id")
        self.ident = ident if ident is not None and ident.cls == "Fn" else None
        self.count = 0

    def command_zero(self) -> float | None:
        d, failures, written = self.drive, [], 0
        for entry in (self.jog, self.reference, self.ident):
            if entry is None or (entry is self.reference and entry.cls == "Pn"):
                continue  # a reference held in a parameter (SDC PN22) is the user's setting: the servo-off stops it
            try:
                d.write_raw(entry, 0)
                written += 1
            except DeviceError as exc:
                failures.append(exc)
        if self.drive.profile.forced_inputs is not None:
            release_forcing(self.drive)  # a forced JOG's inputs, and a wired E-stop's, follow their terminals again
        if failures:
            raise failures[0]
        return None if written else 0.0  # a segment route or a parameter-held reference: the servo-off stops it

    def keep_alive(self) -> None:
        if self.keepalive is not None:
            self.count = (self.count + 1) & 0xFFFF
            self.drive.write_raw(self.keepalive, self.count if self.keepalive.max >= 0xFFFF else 1)

    def leave(self) -> None:
        if self.servo is not None:
            self.drive.write_raw(self.servo, 0)

    def release(self) -> bool:
        release_forcing(self.drive)
        return self.drive.profile.forced_inputs is not None


def stop_drive(drive: Drive, wait_s: float = 3.0, clock: Clock | None = None) -> StopReport:
    """`servotool stop` on one drive: zero speed, rest (bounded by wait_s), servo off, forced inputs released, read
    back. No identity check, journal or lock comes first (a running servotool process holds the lock)."""
    return stop_sequence(drive, DriveHalt(drive), {}, wait_s=wait_s, clock=clock)
