"""Hand-over of the running machine between processes that serve one simulated drive.

The drive stays powered between CLI invocations: the firmware's running state (mode, latched alarm, position, I^2t,
an identification in progress) is kept in the state file with the parameters, so the next process continues where
the last one stopped. A power cycle removes it and the next process starts afresh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from servotool.clock import Clock
from servotool.sim.identification import Identification
from servotool.sim.registers import MACHINE_STATE_KEY

FIRMWARE_MODES = ("off", "jog", "speed", "servo", "ident", "stopping")


@dataclass
class MachineState:
    """The firmware's running state in this process's clock (times already shifted into it)."""

    mode: str = "off"
    jog_dir: int = 0
    last_host: float | None = None  # None: unknown, keep the power-on value
    recorded: bool = False  # the latched alarm is already in the history
    ident: Identification | None = None
    plant: dict[str, Any] | None = None  # Plant.state()
    plant_shift: float = 0.0  # for Plant.restore(plant, shift)


@dataclass(frozen=True)
class RunningSummary:
    """What `sim show` reports of a stored running state."""

    servo_on: bool
    alarm: str | None
    position_rev: float


class Handover:
    """Stores this process's running state in the state file, and takes over what another process stored."""

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        self.seq: int | None = None  # which stored state this process's state is (None: not stored)

    def _wall_offset(self) -> float:
        return self.clock.wall() - self.clock.now()

    def store(self, extra: dict[str, Any], state: MachineState) -> None:
        """Put the running state into the state file's extra data, about to be written."""
        stored = extra.get(MACHINE_STATE_KEY)
        seq = stored.get("seq", 0) if isinstance(stored, dict) else 0
        self.seq = (seq if isinstance(seq, int) else 0) + 1
        extra[MACHINE_STATE_KEY] = {
            "seq": self.seq,
            "wall_offset": self._wall_offset(),
            "plant": state.plant,
            "mode": state.mode,
            "jog_dir": state.jog_dir,
            "last_host": state.last_host,
            "recorded": state.recorded,
            "ident": state.ident.stored() if state.ident is not None else None,
        }

    def take(self, extra: dict[str, Any]) -> MachineState | None:
        """What to continue from: None to keep this process's state; a MachineState to start afresh from (a
        default one after a power cycle)."""
        stored = extra.get(MACHINE_STATE_KEY)
        if not isinstance(stored, dict):
            if self.seq is None:
                return None
            self.seq = None  # stored before, gone now: the drive was power-cycled
            return MachineState()
        if stored.get("seq") == self.seq:
            return None  # our own state (the file changed for another reason)
        seq = stored.get("seq")
        self.seq = seq if isinstance(seq, int) else None
        return _unpack(stored, self._wall_offset())


def _unpack(stored: dict[str, Any], wall_offset: float) -> MachineState:
    offset = stored.get("wall_offset")
    shift = float(offset) - wall_offset if _number(offset) else 0.0
    last_host = stored.get("last_host")
    plant = stored.get("plant")
    return MachineState(
        mode=str(stored["mode"]) if stored.get("mode") in FIRMWARE_MODES else "off",
        jog_dir=_int(stored.get("jog_dir"), 0),
        last_host=float(last_host) + shift if _number(last_host) else None,
        recorded=stored.get("recorded") is True,
        ident=Identification.from_stored(stored.get("ident"), shift),
        plant=plant if isinstance(plant, dict) else None,
        plant_shift=shift,
    )


def running_summary(extra: dict[str, Any]) -> RunningSummary | None:
    """The stored running state (servo, latched alarm, position); None when the drive was just powered on."""
    stored = extra.get(MACHINE_STATE_KEY)
    plant = stored.get("plant") if isinstance(stored, dict) else None
    if not isinstance(plant, dict):
        return None
    theta, alarm = plant.get("theta"), plant.get("alarm")
    return RunningSummary(
        servo_on=plant.get("mode") not in ("off", None),
        alarm=alarm if isinstance(alarm, str) else None,
        position_rev=theta / (2 * math.pi) if _number(theta) else 0.0,
    )


def _number(value: object) -> bool:
    return isinstance(value, (int, float))


def _int(value: object, default: int) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else default
