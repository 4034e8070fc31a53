"""Alarms: read the current alarm and its history, clear it, through the profile's roles."""

from __future__ import annotations

import re
from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import VerifyError
from servotool.model.profile import Profile

FEATURE = "alarm"


@dataclass(frozen=True)
class AlarmState:
    """One alarm code as the profile explains it; `active` is true only for the drive's current alarm."""

    code: int
    display: str
    name: str
    clearable: bool | None
    active: bool
    known: bool = True

    def as_json(self) -> dict[str, object]:
        return {
            "code": self.code,
            "display": self.display,
            "name": self.name,
            "active": self.active,
            "clearable": self.clearable,
            "known": self.known,
        }


def describe(profile: Profile, code: int, *, active: bool | None = None) -> AlarmState:
    """The profile's name for an alarm code; a code the profile does not list is shown as unknown, not guessed.

    `active` defaults to "the code is not zero", which is right for the current-alarm register only.
    """
    is_active = code != 0 if active is None else active
    if code == 0:
        return AlarmState(0, "-", "no alarm", None, False)
    known = profile.alarm(code)
    if known is None:
        return AlarmState(
            code, f"0x{code:04X}", f"unknown alarm (not in the {profile.id} profile)", None, is_active, known=False
        )
    return AlarmState(code, known.display, known.name, known.clearable, is_active)


def current(drive: Drive) -> AlarmState:
    return describe(drive.profile, drive.read_role("alarm_code", FEATURE).raw)


def confirmed(drive: Drive) -> AlarmState | None:
    """The drive's alarm when two reads in a row report it (one stray reply is no alarm); None without one or
    where the profile maps no alarm code."""
    if drive.profile.role("alarm_code") is None:
        return None
    state = current(drive)
    return state if state.active and current(drive).code == state.code else None


def history_roles(profile: Profile) -> list[str]:
    roles = [r for r in profile.roles if re.fullmatch(r"alarm_history_\d+", r)]
    return sorted(roles, key=lambda r: int(r.rsplit("_", 1)[1]))


def history(drive: Drive) -> list[AlarmState]:
    """Alarm history, most recent first, from the profile's alarm_history_N roles.

    Past alarms are not active; the most recent entry is, when it is the alarm the drive reports now.
    """
    roles = history_roles(drive.profile)
    if not roles:
        drive.profile.need_role("alarm_history_1", "alarm history")
    readings = drive.read_entries([drive.profile.need_role(r, "alarm history") for r in roles])
    now = current(drive).code if drive.profile.role("alarm_code") is not None else 0
    return [
        describe(drive.profile, r.raw, active=(n == 0 and r.raw != 0 and r.raw == now)) for n, r in enumerate(readings)
    ]


def clear(drive: Drive) -> AlarmState:
    """Reset the alarm and read it again; VerifyError when it is still active (cause not gone)."""
    drive.trigger("alarm_reset", "alarm clear")
    after = current(drive)
    if after.active:
        why = (
            " (not clearable: needs a power cycle or repair)"
            if after.clearable is False
            else " (its cause is still present)"
        )
        raise VerifyError(f"alarm {after.display} {after.name} is still active after reset{why}")
    return after
