"""Drive status read by role: servo state."""

from __future__ import annotations

from servotool.drive import Drive
from servotool.model.roles import status_bit


def servo_is_on(drive: Drive) -> bool | None:
    """Servo state from the servo_status role (None when the profile has no such role)."""
    entry = drive.profile.role("servo_status")
    if entry is None:
        return None
    raw = drive.read_entries([entry])[0].raw
    bit = status_bit(entry, "servo_on")
    return bool(raw >> bit & 1) if bit is not None else raw != 0
