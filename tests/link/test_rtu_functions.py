"""FC04 (input registers) through the RTU master's frames: the same shapes as FC03, matched on their own function."""

from __future__ import annotations

import pytest

from servotool.errors import ModbusException
from servotool.link.crc import with_crc
from servotool.link.rtu import READ, READ_INPUT, NotAnswer, Request


def test_fc04_request_and_reply_frames():
    req = Request(1, READ_INPUT, 0x2100, 2)
    assert req.frame == with_crc(bytes([1, 4, 0x21, 0x00, 0, 2]))
    reply = with_crc(bytes([1, 4, 4, 0x01, 0x90, 0x01, 0x91]))
    assert req.reply_length(reply[:3]) == len(reply)
    assert req.answer(reply, "read") == [400, 401]


def test_an_fc03_reply_does_not_answer_fc04_and_exception_01_is_raised():
    req = Request(1, READ_INPUT, 0x2100, 1)
    with pytest.raises(NotAnswer, match="function 3"):
        req.reply_length(with_crc(bytes([1, READ, 2, 0, 1]))[:3])
    refused = with_crc(bytes([1, 0x84, 1]))
    assert req.reply_length(refused[:2]) == 5
    with pytest.raises(ModbusException) as exc:
        req.answer(refused, "read")
    assert exc.value.code == 1


class _Device:
    """A wire to a device (a PLC, say) that has coils and input registers: FC01 bits from `coils`, FC04 words
    from `inputs`, each answered at once."""

    def __init__(self, coils: list[int], inputs: dict[int, int]) -> None:
        self.coils, self.inputs, self.reply = coils, inputs, b""

    def send(self, frame: bytes) -> None:
        fc, address, count = frame[1], int.from_bytes(frame[2:4], "big"), int.from_bytes(frame[4:6], "big")
        if fc == 1:
            packed = bytearray((count + 7) // 8)
            for i, bit in enumerate(self.coils[address : address + count]):
                packed[i // 8] |= bit << (i % 8)
            self.reply = with_crc(bytes([1, 1, len(packed)]) + packed)
        elif fc == 5:
            self.coils[address] = 1 if frame[4] == 0xFF else 0
            self.reply = frame
        elif fc == 15:
            for i in range(count):
                self.coils[address + i] = frame[7 + i // 8] >> (i % 8) & 1
            self.reply = with_crc(frame[:6])
        elif fc == 4:
            data = b"".join(self.inputs[a].to_bytes(2, "big") for a in range(address, address + count))
            self.reply = with_crc(bytes([1, 4, len(data)]) + data)
        else:
            self.reply = with_crc(bytes([1, fc | 0x80, 1]))

    def recv(self, timeout: float) -> bytes:
        data, self.reply = self.reply, b""
        return data


def test_the_exchange_reads_bits_and_input_registers_by_their_function():
    from servotool.link.exchange import Exchange

    coils = [1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1]
    ex = Exchange(_Device(coils, {7: 0xBEEF, 8: 12}), timeout=0.2, retries=0)
    assert ex.read(1, 0, 11, fc=1) == coils  # two bytes, the second one partly used
    assert ex.read(1, 2, 3, fc=1) == coils[2:5]
    assert ex.read(1, 7, 2, fc=4) == [0xBEEF, 12]
    with pytest.raises(ModbusException) as exc:
        ex.read(1, 7, 1)  # this device has no holding registers: 01
    assert exc.value.code == 1


def test_fc01_request_frame_and_bit_unpacking():
    req = Request(1, 1, 0x0013, 10)
    assert req.frame == with_crc(bytes([1, 1, 0, 0x13, 0, 10]))
    assert req.data_bytes == 2
    reply = with_crc(bytes([1, 1, 2, 0b1100_1101, 0b0000_0001]))
    assert req.reply_length(reply[:3]) == len(reply)
    assert req.answer(reply, "read") == [1, 0, 1, 1, 0, 0, 1, 1, 1, 0]
    with pytest.raises(NotAnswer, match="data bytes"):
        req.reply_length(with_crc(bytes([1, 1, 4, 0, 0, 0, 0]))[:3])  # a width that is not this read's


def test_the_exchange_writes_coils_with_fc05_and_fc15_and_they_read_back():
    from servotool.link.exchange import Exchange

    device = _Device([0] * 12, {})
    ex = Exchange(device, timeout=0.2, retries=0)
    ex.write(1, 3, [1], multiple=False, coils=True)
    assert device.coils[3] == 1 and ex.read(1, 3, 1, fc=1) == [1]
    ex.write(1, 0, [1, 0, 1, 1, 0, 0, 0, 1, 1, 0], coils=True)
    assert ex.read(1, 0, 10, fc=1) == [1, 0, 1, 1, 0, 0, 0, 1, 1, 0]


def test_coil_write_frames():
    assert Request(1, 5, 0x00AC, 1, (1,)).frame == with_crc(bytes([1, 5, 0, 0xAC, 0xFF, 0]))
    assert Request(1, 5, 0x00AC, 1, (0,)).frame == with_crc(bytes([1, 5, 0, 0xAC, 0, 0]))
    many = Request(1, 15, 0x0013, 10, (1, 0, 1, 1, 0, 0, 1, 1, 1, 0))
    assert many.frame == with_crc(bytes([1, 15, 0, 0x13, 0, 10, 2, 0xCD, 0x01]))  # the specification's example
    assert many.answer(with_crc(bytes([1, 15, 0, 0x13, 0, 10])), "write") == []
