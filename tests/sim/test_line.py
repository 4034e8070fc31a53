"""The simulated slave answers as the Modbus specification has it, through pymodbus' server."""

from __future__ import annotations

import socket

import pytest

from servotool.link.crc import with_crc
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim

SILENT = 0.3  # s without an answer that counts as silence


def _frames(address: int) -> list[bytes]:
    a = address.to_bytes(2, "big")
    bodies = [
        b"\x01\x03" + a + b"\x00\x01",  # a read
        b"\x01\x04" + a + b"\x00\x01",  # FC04, which no manual lists: 01
        b"\x01\x03\x00\x01\x00\x02",  # an unmapped address: 02
        b"\x01\x03" + a + b"\x00\x00",  # quantity 0: 03
        b"\x01\x03" + a + b"\x00\x7e",  # quantity 126: 03
        b"\x01\x05" + a + b"\xff\x00",  # a function the drive lacks: 01
        b"\x01\x06" + a + b"\x01\x2c",  # a single write, repeated as the reply
        b"\x01\x06" + a + b"\xff\xff",  # out of the entry's range: 03
        b"\x01\x10" + a + b"\x00\x01\x02\x00\x64",  # a multiple write
        b"\x01\x10" + a + b"\x00\x01\x04\x00\x64\x00\x00",  # a byte count that disagrees: 03
        b"\x09\x03" + a + b"\x00\x01",  # a unit nobody serves: silence
        b"\x00\x06" + a + b"\x00\xc8",  # a broadcast: applied, silence
        b"\x01\x03" + a + b"\x00\x01",  # ... as the read shows
    ]
    return [with_crc(b) for b in bodies] + [b"\x01\x03" + a + b"\x00\x01\x00\x00"]  # a bad CRC: silence


def _over_tcp(port: str, frames: list[bytes]) -> list[bytes]:
    host, _, number = port.removeprefix("tcp://").rpartition(":")
    replies = []
    with socket.create_connection((host, int(number)), timeout=5) as sock:
        for frame in frames:
            sock.sendall(frame)
            sock.settimeout(SILENT)
            try:
                replies.append(sock.recv(256))
            except TimeoutError:
                replies.append(b"")
    return replies


def _exception(fc: int, code: int) -> bytes:
    return with_crc(bytes([1, fc | 0x80, code]))


@pytest.mark.parametrize("profile", ["dsx7e", "is620p"])
def test_the_servers_replies_follow_the_specification(sim_dir, profile):
    """Each request gets what a Modbus slave owes it: data, the exception the specification names, or silence."""
    p = load_profile(profile)
    entry = p.entry(p.roles["inertia_ratio"])
    frames = _frames(entry.address)
    a = entry.address.to_bytes(2, "big")
    sim = EmbeddedSim([build_drive(p, 1)])
    try:
        r = _over_tcp(sim.port, frames)
    finally:
        sim.close()
    assert r[0][:3] == b"\x01\x03\x02" and r[1] == _exception(4, 1)
    assert r[2:6] == [_exception(3, 2), _exception(3, 3), _exception(3, 3), _exception(5, 1)]
    assert r[6] == frames[6]  # a single write is answered by its own frame
    assert r[7] == _exception(6, 3)
    assert r[8] == with_crc(b"\x01\x10" + a + b"\x00\x01")
    assert r[9] == _exception(16, 3)
    assert r[10:12] == [b"", b""]  # unknown unit, broadcast: silence
    assert r[12] == with_crc(b"\x01\x03\x02\x00\xc8")  # the broadcast was applied
    assert r[13] == b""  # a bad CRC: silence
