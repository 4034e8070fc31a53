"""The dead-man beat period host motion must keep, from the drive's watchdog setting."""

from __future__ import annotations

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
    if timeout_s <= 0:          # watchdog disabled
        return default_s
    if timeout_s < 0.06:
        raise UsageError(f"the drive's host watchdog {timeout.code} = {timeout_s * 1000:g} ms is too short "
                         "to keep a motion alive over this link (at least 60 ms)")
    return timeout_s / 3
