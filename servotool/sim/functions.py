"""What the simulated drive's function writes mean: each role's write decoded into a firmware action.

Roles, not vendor codes, say which entry does what, so any profile with the roles gets the behaviour. Motion roles
may sit on parameters (a signed JOG speed, a forced-DI word) rather than Fn entries: their writes act too.
"""

from __future__ import annotations

from typing import Protocol

from servotool.model.codec import raw_to_eng
from servotool.model.profile import Entry
from servotool.model.roles import jog_direction
from servotool.sim.device import FnHandler, SimulatedDrive


class FirmwareActions(Protocol):
    """The drive behaviour the functions trigger (servotool.sim.firmware.Firmware)."""

    def update(self) -> None: ...
    def keep_alive(self) -> None: ...
    def jog(self, direction: int) -> None: ...
    def command_speed(self, rpm: float) -> None: ...
    def servo(self, on: bool) -> None: ...
    def segment_start(self, level: bool) -> None: ...
    def reset_alarm(self) -> None: ...
    def reboot(self) -> None: ...
    def identify(self, start: bool) -> None: ...
    def inputs_changed(self) -> None: ...


def motion_handlers(fw: FirmwareActions, start_value: int = 0) -> dict[str, FnHandler]:
    """Handlers of the host-motion roles, by role (start_value: the segment start bits, which share the servo-on
    entry on a segment route and do not switch the servo on)."""
    return {
        "jog": lambda _d, entry, raw: fw.jog(jog_direction(entry, raw)),
        "speed_reference": lambda _d, entry, raw: fw.command_speed(float(raw_to_eng(entry, raw))),
        "servo_on": lambda _d, _e, raw: fw.servo(bool(raw & ~start_value)),
        "segment_start": lambda _d, _e, raw: fw.segment_start(bool(raw & start_value)),
        "keepalive": lambda _d, _e, _raw: fw.keep_alive(),
    }


def install(drive: SimulatedDrive, fw: FirmwareActions) -> None:
    """Route the drive's function writes, and writes of motion roles held in parameters, to the firmware."""
    dead_man = drive.profile.dead_man
    motion = motion_handlers(fw, dead_man.start_value if dead_man is not None and dead_man.route == "segment" else 0)
    drive.handlers.update(
        {
            **motion,
            "alarm_reset": lambda _d, _e, raw: fw.reset_alarm() if raw else fw.update(),
            "inertia_id": lambda _d, _e, raw: fw.identify(bool(raw)),
            "soft_reset": _soft_reset(drive.handlers.get("soft_reset"), fw),
        }
    )
    by_code: dict[str, list[FnHandler]] = {}
    forced = drive.profile.forced_inputs
    for role, code in drive.profile.roles.items():
        entry = drive.profile.entry(code)
        if forced is not None and role == "jog":
            continue  # a forced-input trigger acts through the input levels (below)
        if role in motion and entry is not None and entry.cls != "Fn":
            by_code.setdefault(entry.code.upper(), []).append(motion[role])
    if forced is not None:
        for code in (forced.switch_code, forced.levels_code):
            by_code.setdefault(code.upper(), []).append(lambda _d, _e, _raw: fw.inputs_changed())

    def parameter_written(d: SimulatedDrive, entry: Entry, raw: int) -> None:
        for handler in by_code.get(entry.code.upper(), []):
            handler(d, entry, raw)

    drive.on_param_change.append(parameter_written)


def _soft_reset(memory_reset: FnHandler | None, fw: FirmwareActions) -> FnHandler:
    """A soft reset reboots the drive: parameters take effect (the device's own handler) and the running state
    starts afresh."""

    def handler(drive: SimulatedDrive, entry: Entry, raw: int) -> None:
        if memory_reset is not None:
            memory_reset(drive, entry, raw)
        if raw == entry.trigger:
            fw.reboot()

    return handler
