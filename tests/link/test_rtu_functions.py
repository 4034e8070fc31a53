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
