"""Drive status read by role: servo state, and speed, servo state and alarm at a glance."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive, Reading
from servotool.model.roles import status_bit
from servotool.ops.alarms import AlarmState, describe


def servo_is_on(drive: Drive) -> bool | None:
    """Servo state from the servo_status role (None when the profile has no such role)."""
    entry = drive.profile.role("servo_status")
    if entry is None:
        return None
    return _servo_on(drive.read_entries([entry])[0])


def _servo_on(status: Reading) -> bool:
    bit = status_bit(status.entry, "servo_on")
    return bool(status.raw >> bit & 1) if bit is not None else status.raw != 0


@dataclass(frozen=True)
class DriveStatus:
    """What a drive says of itself at a glance: speed, servo state, alarm (None where the profile maps no entry)."""

    speed: Reading | None
    servo_on: bool | None
    alarm: AlarmState | None


def glance(drive: Drive) -> DriveStatus:
    """Speed feedback, servo state and current alarm, read together (coalesced where the map allows)."""
    wanted = {role: e for role in ("speed_feedback", "servo_status", "alarm_code") if (e := drive.profile.role(role))}
    got = dict(zip(wanted, drive.read_entries(wanted.values()), strict=True))
    servo = _servo_on(got["servo_status"]) if "servo_status" in got else None
    alarm = describe(drive.profile, got["alarm_code"].raw) if "alarm_code" in got else None
    return DriveStatus(got.get("speed_feedback"), servo, alarm)
