"""The dead-man beat: host motion keeps writing, or the drive's watchdog stops the motor.

One implementation for every motion servotool commands (JOG, identification, step response, the drive's own
identification): the beat period from the drive's watchdog setting, and the beat write itself. With a hardware
dead-man (--heartbeat), each beat also toggles a control line of the USB-RS485 adapter for a watchdog relay wired to
the drive's enable input or main contactor: the line rests low, and stops toggling (low) when the motion ends, when a
beat comes too late for the relay and on every exit (the OS drops the line when the port closes, also after kill -9).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import TypeVar

from servotool.clock import Clock, RealClock, VirtualClock
from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError
from servotool.link.ports import ControlLine
from servotool.model.codec import raw_to_eng

HEARTBEAT_BEATS = 4  # beats per relay time at least: a late beat is caught (at half the time) before the relay drops
# Toggling this long before a motion's first command: the relay closes and, where it switches the drive's main
# contactor, the drive's DC bus charges before anything moves.
HEARTBEAT_LEAD_S = 1.0
# While a computation runs beside a motion (KeepAlive.while_computing), the beat is looked at this many times a beat
# interval: a beat then comes at most a beat interval and this share of one late, plus the host's wake-up.
COMPUTING_LOOKS = 2

T = TypeVar("T")


class HeartbeatMissed(DeviceError):
    """A beat came too late for the watchdog relay: the heartbeat stopped for good (the relay drops the drive)."""


def keepalive_interval_s(drive: Drive, default_s: float = 0.1) -> float:
    """How often host motion must beat: three times per watchdog period (role comm_timeout), else default_s.

    Raises UsageError when the watchdog is too short to keep any motion alive over a serial link.
    """
    if drive.heartbeat_timeout_s is not None:  # the relay needs a beat every quarter of its time
        default_s = min(default_s, drive.heartbeat_timeout_s / HEARTBEAT_BEATS)
    timeout = drive.profile.role("comm_timeout")
    if timeout is None:
        return default_s
    timeout_s = float(raw_to_eng(timeout, drive.read_entries([timeout])[0].raw)) / 1000.0
    if timeout_s <= 0:  # watchdog disabled
        return default_s
    if timeout_s < 0.06:
        raise UsageError(
            f"the drive's host watchdog {timeout.code} = {timeout_s * 1000:g} ms is too short "
            "to keep a motion alive over this link (at least 60 ms)"
        )
    return min(timeout_s / 3, default_s) if drive.heartbeat_timeout_s is not None else timeout_s / 3


class Heartbeat:
    """The toggling of one control line for a retriggerable watchdog relay: at every beat, unless the beat comes
    later than half the relay's time after the one before (the relay may be about to drop the drive: toggling on
    would switch it on again mid-motion), which stops it for good."""

    def __init__(self, line: ControlLine, timeout_s: float, clock: Clock) -> None:
        self.line, self.timeout_s, self.clock = line, timeout_s, clock
        self.last: float | None = None
        self.toggles = 0
        self.stopped = False

    def toggle(self) -> None:
        """One toggle, now; HeartbeatMissed (and stopped, the line low) when it comes too late. Once stopped it
        toggles no more (the stop that follows a missed beat still beats the drive's own watchdog)."""
        now = self.clock.now()
        if self.stopped:
            return
        if self.last is not None and now - self.last > self.timeout_s / 2:
            self.stop()
            raise HeartbeatMissed(
                f"a keep-alive beat came {(now - self.last) * 1000:.0f} ms after the one before, over half the "
                f"watchdog relay's {self.timeout_s * 1000:g} ms: the heartbeat ({self.line.name}) stopped and the "
                "relay drops the drive's enable"
            )
        self.line.set(not self.line.level)
        self.last, self.toggles = now, self.toggles + 1

    def stop(self) -> None:
        """No more toggles; the line low (its resting level, as the OS leaves it when the port closes)."""
        self.stopped = True
        if self.line.level:
            self.line.set(False)


class KeepAlive:
    """The beat of one drive: writes its keep-alive entry (role keepalive: a counter where it takes 16 bits,
    else 1); a drive without one is kept alive by re-sending the running command (`resend`), if any."""

    def __init__(
        self, drive: Drive, interval_s: float, clock: Clock | None = None, resend: Callable[[], None] | None = None
    ) -> None:
        self.drive = drive
        self.entry = drive.profile.role("keepalive")
        self.interval_s = interval_s
        self.clock = clock or RealClock()
        self.resend = resend
        self.count = 0
        self.last = self.clock.now()
        line, relay_s = drive.heartbeat_line, drive.heartbeat_timeout_s
        self.heartbeat = Heartbeat(line, relay_s, self.clock) if line is not None and relay_s is not None else None

    @classmethod
    def for_drive(cls, drive: Drive, clock: Clock | None = None, resend: Callable[[], None] | None = None) -> KeepAlive:
        """A beat at the drive's watchdog rate (see keepalive_interval_s)."""
        return cls(drive, keepalive_interval_s(drive), clock, resend)

    def due(self, now: float | None = None) -> bool:
        """Whether a beat is due: interval_s has passed since the last write that kept the drive alive."""
        return self.due_after(self.interval_s, now)

    def due_after(self, seconds: float, now: float | None = None) -> bool:
        """Whether `seconds` have passed since the last write that kept the drive alive."""
        return (self.clock.now() if now is None else now) - self.last >= seconds

    def sent(self) -> None:
        """A motion command just went out: the drive's watchdog counts it as a beat."""
        self.last = self.clock.now()

    def beat(self) -> None:
        """One beat, now (and the heartbeat's toggle: HeartbeatMissed when it came too late)."""
        if self.heartbeat is not None:
            self.heartbeat.toggle()
        self.count = (self.count + 1) & 0xFFFF
        if self.entry is not None:
            self.drive.write_raw(self.entry, self.count if self.entry.max >= 0xFFFF else 1)
        elif self.resend is not None:
            self.resend()
        self.last = self.clock.now()

    def beat_if_due(self) -> None:
        if self.due():
            self.beat()

    def toggle_if_due(self) -> None:
        """The heartbeat's toggle alone where a beat's interval has passed since its last (a motion whose drive
        needs fewer writes than the relay needs toggles)."""
        hb = self.heartbeat
        if hb is not None and (hb.last is None or self.clock.now() - hb.last >= self.interval_s):
            hb.toggle()

    def while_computing(self, work: Callable[[], T], feed: Callable[[float], None]) -> T:
        """work() (a computation that touches no link: a fit between moves) on a thread of its own while this one
        keeps the drive alive: feed(lead_s), the motion's own beat (it decides what to write), is called once first and
        then every 1/COMPUTING_LOOKS of a beat interval until work ends; its result, or its exception, comes back here.
        One beat before a computation is not enough: on a busy host its time is several times its CPU time, past a
        drive's watchdog. On a virtual clock work() runs here, and then the clock's computing_s passes, fed as on a
        real host."""
        feed(self.interval_s)
        if not isinstance(self.clock, RealClock):
            result = work()
            end = self.clock.now() + (self.clock.computing_s if isinstance(self.clock, VirtualClock) else 0.0)
            while self.clock.now() < end:
                self.clock.sleep(min(self.interval_s / COMPUTING_LOOKS, end - self.clock.now()))
                feed(self.interval_s)
            return result
        outcome: list[T] = []
        failed: list[BaseException] = []
        done = threading.Event()

        def run() -> None:
            try:
                outcome.append(work())
            except BaseException as exc:  # raised again on the motion's thread
                failed.append(exc)
            finally:
                done.set()

        threading.Thread(target=run, name="servotool-compute", daemon=True).start()
        while not done.wait(self.interval_s / COMPUTING_LOOKS):
            feed(self.interval_s)
        if failed:
            raise failed[0]
        return outcome[0]

    def heartbeat_lead(self, idle: Callable[[float], None]) -> None:
        """Before a motion's first command: toggle for HEARTBEAT_LEAD_S (idle: how to wait between toggles)."""
        hb = self.heartbeat
        if hb is None:
            return
        end = self.clock.now() + HEARTBEAT_LEAD_S
        while self.clock.now() < end:
            hb.toggle()
            idle(min(self.interval_s, max(0.0, end - self.clock.now())))
        hb.toggle()

    def stop_heartbeat(self) -> None:
        """The motion has ended: no more toggles, the line low."""
        if self.heartbeat is not None:
            self.heartbeat.stop()
