"""The simulator answers --port sim in this process exactly as its pymodbus server answers on a port."""

from __future__ import annotations

import socket

import pytest

from servotool.clock import VirtualClock
from servotool.link.rtu import with_crc
from servotool.model.loader import load_profile
from servotool.session import SimWire
from servotool.sim.firmware import build_drive
from servotool.sim.line import Line
from servotool.sim.server import EmbeddedSim
from servotool.sim.virtual import wire_time

SILENT = 0.3        # s without an answer that counts as silence


def _frames(address: int) -> list[bytes]:
    a = address.to_bytes(2, "big")
    bodies = [
        b"\x01\x03" + a + b"\x00\x01",                      # a read
        b"\x01\x04" + a + b"\x00\x01",                      # FC04 reads the same registers
        b"\x01\x03\x00\x01\x00\x02",                        # an unmapped address: 02
        b"\x01\x03" + a + b"\x00\x00",                      # quantity 0: 03
        b"\x01\x03" + a + b"\x00\x7e",                      # quantity 126: 03
        b"\x01\x05" + a + b"\xff\x00",                      # a function the drive lacks: 01
        b"\x01\x06" + a + b"\x01\x2c",                      # a single write, repeated as the reply
        b"\x01\x06" + a + b"\xff\xff",                      # out of the entry's range: 03
        b"\x01\x10" + a + b"\x00\x01\x02\x00\x64",          # a multiple write
        b"\x01\x10" + a + b"\x00\x01\x04\x00\x64\x00\x00",  # a byte count that disagrees: 03
        b"\x09\x03" + a + b"\x00\x01",                      # a unit nobody serves: silence
        b"\x00\x06" + a + b"\x00\xc8",                      # a broadcast: applied, silence
        b"\x01\x03" + a + b"\x00\x01",                      # ... as the read shows
    ]
    return [with_crc(b) for b in bodies] + [b"\x01\x03" + a + b"\x00\x01\x00\x00"]    # a bad CRC: silence


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


def _in_process(wire: SimWire, frames: list[bytes]) -> list[bytes]:
    replies = []
    for frame in frames:
        wire.send(frame)
        replies.append(wire.recv(SILENT))
    return replies


@pytest.mark.parametrize("profile", ["dsx7e", "is620p"])
def test_in_process_replies_equal_the_servers(sim_dir, monkeypatch, profile):
    p = load_profile(profile)
    entry = p.entry(p.roles["inertia_ratio"])
    frames = _frames(entry.address)
    monkeypatch.setenv("SERVOTOOL_SIM_DIR", str(sim_dir / "served"))
    sim = EmbeddedSim([build_drive(p, 1)])
    try:
        served = _over_tcp(sim.port, frames)
    finally:
        sim.close()
    monkeypatch.setenv("SERVOTOOL_SIM_DIR", str(sim_dir / "in-process"))
    assert _in_process(SimWire(Line([build_drive(p, 1)])), frames) == served
    assert served[0] and served[-4] == b"" and served[-1] == b""


def test_a_silent_unit_costs_the_timeout_and_a_reply_its_line_time(sim_dir):
    clock = VirtualClock(100.0)
    drive = build_drive(load_profile("dsx7e"), 1, clock, persist=False)
    drive.settings["line_baud"] = 9600
    wire = SimWire(Line([drive]), clock)
    wire.send(with_crc(b"\x07\x03\x20\x04\x00\x01"))
    assert wire.recv(0.5) == b"" and clock.now() == 100.5
    wire.send(with_crc(b"\x01\x03\x20\x04\x00\x01"))
    assert wire.recv(0.001) == b""             # not yet on the line at 9600 Bd
    assert len(wire.recv(0.5)) == 7 and 100.5 + wire_time(3, 1, 9600) <= clock.now() < 100.6
