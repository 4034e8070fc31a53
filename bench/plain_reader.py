"""An independent reader of a drive served by `servotool sim serve --port tcp://...`: pymodbus' own client (RTU
frames over TCP), none of servotool's link or drive code, so that servotool's recovery cannot tidy anything up
before it is read. The profile gives only the addresses and how the words decode.

What it reads (`Snapshot`): the motor speed, the servo state, the position counter, the alarm code and, where the
drive forces its inputs for motion (SD25 So-58), the forcing mode. The servo state is the drive's status bit where
the profile has one (DSX7E 5E00h, SD25 L944 SON-O), else the servo-on entry itself (IS620P H31-00 bit 0 = VDI1 S-ON,
SDC PN95): IS620P's H30-00 servo status is not decoded in its manual.

    python bench/plain_reader.py tcp://127.0.0.1:PORT PROFILE   # one reading, as JSON
"""

from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from servotool.model.codec import raw_to_eng, words_to_raw
from servotool.model.loader import load_profile
from servotool.model.profile import Entry, Profile
from servotool.model.roles import status_bit

FORCING_CODES = {"sd25": "So-58"}  # the drive's forced-input mode, released when motion ends


@dataclass(frozen=True)
class Snapshot:
    speed_rpm: float
    servo_on: bool
    position: int | None  # raw counter
    alarm: int | None
    forcing: int | None  # the forced-input mode (SD25 So-58), None where the drive forces nothing


class PlainReader:
    """Reads one unit of a served simulated drive with pymodbus; use as a context manager."""

    def __init__(self, port: str, profile: str | Profile, unit: int = 1) -> None:
        host, _, number = port.removeprefix("tcp://").rpartition(":")
        self.profile = load_profile(profile) if isinstance(profile, str) else profile
        self.unit = unit
        self.client = ModbusTcpClient(host, port=int(number), framer=FramerType.RTU, timeout=1.0, retries=3)

    def __enter__(self) -> PlainReader:
        if not self.client.connect():
            raise ConnectionError("plain reader: cannot connect")
        return self

    def __exit__(self, *_exc: object) -> None:
        self.client.close()

    def raw(self, entry: Entry) -> int:
        reply = self.client.read_holding_registers(entry.address, count=entry.words, device_id=self.unit)
        if reply.isError():
            raise ConnectionError(f"plain reader: {entry.code}: {reply}")
        return words_to_raw(entry, list(reply.registers))

    def role(self, role: str) -> Entry | None:
        return self.profile.role(role)

    def servo_on(self) -> bool:
        status = self.role("servo_status")
        if status is not None and (bit := status_bit(status, "servo_on")) is not None:
            return bool(self.raw(status) >> bit & 1)
        servo = self.role("servo_on")
        assert servo is not None, f"{self.profile.id}: no servo state to read"
        return bool(self.raw(servo) & 1)

    def snapshot(self) -> Snapshot:
        speed = self.role("speed_feedback")
        assert speed is not None
        position, alarm = self.role("position_feedback"), self.role("alarm_code")
        forcing = FORCING_CODES.get(self.profile.id)
        return Snapshot(
            float(raw_to_eng(speed, self.raw(speed))),
            self.servo_on(),
            self.raw(position) if position is not None else None,
            self.raw(alarm) if alarm is not None else None,
            self.raw(self.profile.entry(forcing)) & 0xF if forcing else None,
        )

    def settings(self) -> dict[str, int]:
        """Every readable parameter (class Pn) of the profile, code -> raw: what a command left on the drive."""
        return {e.code: self.raw(e) for e in self.profile.entries if e.cls == "Pn" and e.readable}

    def revolutions(self, before: int, after: int) -> float:
        """Revolutions between two raw position counter readings (shortest way round a 32-bit wrap)."""
        motor = self.profile.motor
        assert motor is not None
        step = (after - before) % (1 << 32)
        step = step - (1 << 32) if step >= 1 << 31 else step
        return step / motor.counts_per_rev


if __name__ == "__main__":
    with PlainReader(sys.argv[1], sys.argv[2]) as reader:
        print(json.dumps(asdict(reader.snapshot())))
