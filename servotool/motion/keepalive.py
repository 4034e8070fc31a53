"""The dead-man beat: host motion keeps writing, or the drive's watchdog stops the motor.

One implementation for every motion servotool commands (JOG, identification, step response, the drive's own
identification): the beat period from the drive's watchdog setting, and the beat write itself.
"""

from __future__ import annotations

from collections.abc import Callable

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng


def keepalive_interval_s(drive: Drive, default_s: float = 0.1) -> float:
    """How often host motion must beat: three times per watchdog period (role comm_timeout), else default_s.

    Raises UsageError when the watchdog is too short to keep any motion alive over a serial link.
    """
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
    return timeout_s / 3


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
        """One beat, now."""
        self.count = (self.count + 1) & 0xFFFF
        if self.entry is not None:
            self.drive.write_raw(self.entry, self.count if self.entry.max >= 0xFFFF else 1)
        elif self.resend is not None:
            self.resend()
        self.last = self.clock.now()

    def beat_if_due(self) -> None:
        if self.due():
            self.beat()
