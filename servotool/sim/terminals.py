"""The simulated drive's output monitor: each output shows the state of the function its parameter assigns.

Only what the profile's `io` section names: an output whose function the manual's table gives a simulated state
(`sim:` ready, servo_on, ...) follows that state; any other output stays off, as nothing the manual documents
drives it here. The assignment in effect counts (a changed one acts after a power cycle, as on the drive). Inputs
are not set here: a drive sees what is wired to them (nothing, on the simulator) or what the host forces.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.model.codec import part_value
from servotool.model.profile import Profile
from servotool.model.terminals import IoFunction, split_part
from servotool.sim.registers import RegisterBank

ROTATING_RPM = 20.0  # a motor turning faster than this is rotating (TGON); the simulator's threshold
ZERO_SPEED_RPM = 10.0  # slower than this is zero speed (ZERO, and positioning complete while holding)


@dataclass(frozen=True)
class DriveState:
    """What the drive's output functions report, as the simulator knows it."""

    alarm: bool
    servo_on: bool
    speed_rpm: float

    def shows(self, state: str) -> bool:
        rpm = abs(self.speed_rpm)
        return {
            "ready": not self.alarm,
            "servo_on": self.servo_on,
            "rotating": rpm > ROTATING_RPM,
            "zero_speed": rpm < ZERO_SPEED_RPM,
            "in_position": self.servo_on and rpm < ZERO_SPEED_RPM,
            "alarm": self.alarm,
            "brake_released": self.servo_on,
        }.get(state, False)


def output_word(profile: Profile, bank: RegisterBank, state: DriveState) -> int | None:
    """The outputs monitor's value for this state; None where the profile maps no outputs."""
    outputs = profile.io.outputs if profile.io is not None else None
    if outputs is None:
        return None
    word = 0
    for t in outputs.terminals:
        function: IoFunction | None = t.fixed
        if function is None:
            code, part = split_part(t.function)
            entry = profile.entry(code)
            function = outputs.function(t, part_value(entry, bank.effective_value(entry.code), part))
        if function is not None and function.sim and state.shows(function.sim):
            word |= 1 << t.bit
    return word


def refresh_outputs(profile: Profile, bank: RegisterBank, state: DriveState) -> None:
    word = output_word(profile, bank, state)
    if word is not None and profile.io is not None and profile.io.outputs is not None:
        bank.set_live(profile.io.outputs.monitor, word)
