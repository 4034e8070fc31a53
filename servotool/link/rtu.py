"""Modbus RTU frames as a master sends and checks them: requests, the reply each one expects, CRC.

Pure Python: the exchange logic needs to see every byte to decide whether a reply answers its request, which a
client library's lenient frame hunting hides.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.errors import ModbusException
from servotool.link.crc import crc_ok, with_crc

READ_COILS, READ_DISCRETE, READ, READ_INPUT, WRITE_ONE, WRITE_MANY = 1, 2, 3, 4, 6, 16
REGISTER_READS = (READ, READ_INPUT)  # holding and input registers: the same request and reply shapes
BIT_READS = (READ_COILS, READ_DISCRETE)  # coils and discrete inputs: the same request, bits packed in the reply
WRITE_COIL, WRITE_COILS = 5, 15  # values 0/1; FC05 sends a coil as 0xFF00 or 0x0000
REPEATED_WRITES = (WRITE_COIL, WRITE_ONE)  # single writes, whose reply repeats the request
EXCEPTION_LENGTH = 5


class NotAnswer(Exception):
    """Bytes that are not the answer to the request: garbled (bad CRC or framing) or a valid frame for another."""

    def __init__(self, garbled: bool, why: str) -> None:
        super().__init__(why)
        self.garbled = garbled


@dataclass(frozen=True)
class Request:
    """One request: FC03/FC04 read of `count` registers (FC01/FC02: bits), FC06 write of one, or FC16 write of
    `values`."""

    unit: int
    fc: int
    address: int
    count: int
    values: tuple[int, ...] = ()

    @property
    def reads(self) -> bool:
        """Whether it reads (FC03 holding, FC04 input registers; FC01 coils, FC02 discrete inputs)."""
        return self.fc in REGISTER_READS or self.fc in BIT_READS

    @property
    def repeated(self) -> bool:
        """Whether its reply repeats the request byte for byte (FC05, FC06)."""
        return self.fc in REPEATED_WRITES

    @property
    def data_bytes(self) -> int:
        """The data bytes a read's reply carries: two a register, or the bits packed eight to a byte."""
        return (self.count + 7) // 8 if self.fc in BIT_READS else 2 * self.count

    @property
    def frame(self) -> bytes:
        head = bytes([self.unit, self.fc]) + self.address.to_bytes(2, "big")
        if self.reads:
            return with_crc(head + self.count.to_bytes(2, "big"))
        if self.fc == WRITE_ONE:
            return with_crc(head + self.values[0].to_bytes(2, "big"))
        if self.fc == WRITE_COIL:
            return with_crc(head + (b"\xff\x00" if self.values[0] else b"\x00\x00"))
        if self.fc == WRITE_COILS:
            packed = bytearray((len(self.values) + 7) // 8)
            for i, bit in enumerate(self.values):
                packed[i // 8] |= (1 if bit else 0) << (i % 8)
            return with_crc(head + len(self.values).to_bytes(2, "big") + bytes([len(packed)]) + packed)
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
        if not self.reads:
            return 8
        if len(head) < 3:
            return None
        if head[2] != self.data_bytes:
            raise NotAnswer(False, f"a reply with {head[2]} data bytes")
        return 5 + head[2]

    def answer(self, frame: bytes, what: str) -> list[int]:
        """The registers a complete reply frame carries (writes: []); NotAnswer when it does not answer this
        request, ModbusException for an exception reply."""
        if not crc_ok(frame):
            raise NotAnswer(True, "bad CRC")
        if frame[1] & 0x80:
            raise ModbusException(frame[2], what)
        if self.fc in BIT_READS:
            data = frame[3:-2]
            return [data[i // 8] >> (i % 8) & 1 for i in range(self.count)]
        if self.reads:
            data = frame[3:-2]
            return [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]
        echoed = int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big")
        expected = (self.address, int.from_bytes(self.frame[4:6], "big") if self.repeated else self.count)
        if echoed != expected:
            raise NotAnswer(False, f"an acknowledgement of {echoed[1]} at {echoed[0]}")
        return []
