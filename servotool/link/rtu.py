"""Modbus RTU frames as a master sends and checks them: requests, the reply each one expects, CRC.

Pure Python: the exchange logic needs to see every byte to decide whether a reply answers its request, which a
client library's lenient frame hunting hides.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.errors import ModbusException
from servotool.link.crc import crc_ok, with_crc

READ, WRITE_ONE, WRITE_MANY = 3, 6, 16
EXCEPTION_LENGTH = 5


class NotAnswer(Exception):
    """Bytes that are not the answer to the request: garbled (bad CRC or framing) or a valid frame for another."""

    def __init__(self, garbled: bool, why: str) -> None:
        super().__init__(why)
        self.garbled = garbled


@dataclass(frozen=True)
class Request:
    """One request: FC03 read of `count` registers, FC06 write of one, or FC16 write of `values`."""

    unit: int
    fc: int
    address: int
    count: int
    values: tuple[int, ...] = ()

    @property
    def frame(self) -> bytes:
        head = bytes([self.unit, self.fc]) + self.address.to_bytes(2, "big")
        if self.fc == READ:
            return with_crc(head + self.count.to_bytes(2, "big"))
        if self.fc == WRITE_ONE:
            return with_crc(head + self.values[0].to_bytes(2, "big"))
        data = b"".join(v.to_bytes(2, "big") for v in self.values)
        return with_crc(head + len(self.values).to_bytes(2, "big") + bytes([len(data)]) + data)

    def reply_length(self, head: bytes) -> int | None:
        """Length of the reply frame that starts with `head`, None until enough bytes are in; NotAnswer when the
        head already shows it answers something else (another unit, function or register count)."""
        if len(head) < 2:
            return None
        if head[0] != self.unit:
            raise NotAnswer(False, f"a reply from unit {head[0]}")
        if head[1] == self.fc | 0x80:
            return EXCEPTION_LENGTH
        if head[1] != self.fc:
            raise NotAnswer(False, f"a reply to function {head[1] & 0x7F}")
        if self.fc != READ:
            return 8
        if len(head) < 3:
            return None
        if head[2] != 2 * self.count:
            raise NotAnswer(False, f"a reply with {head[2]} data bytes")
        return 5 + head[2]

    def answer(self, frame: bytes, what: str) -> list[int]:
        """The registers a complete reply frame carries (writes: []); NotAnswer when it does not answer this
        request, ModbusException for an exception reply."""
        if not crc_ok(frame):
            raise NotAnswer(True, "bad CRC")
        if frame[1] & 0x80:
            raise ModbusException(frame[2], what)
        if self.fc == READ:
            data = frame[3:-2]
            return [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
        echoed = int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big")
        expected = (self.address, self.values[0] if self.fc == WRITE_ONE else self.count)
        if echoed != expected:
            raise NotAnswer(False, f"an acknowledgement of {echoed[1]} at {echoed[0]}")
        return []
