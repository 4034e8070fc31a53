"""The link's promises: coalesced reads within the profile's limits, errors that name the entry and the cause."""

from __future__ import annotations

import socket
import threading

import pytest

from servotool.drive import Drive, coalesce_reads
from servotool.errors import DeviceError, VerifyError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


class CountingLink:
    """A Link straight into a simulated drive that records every request."""

    def __init__(self, sim) -> None:
        self.sim, self.reads = sim, []

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0)) -> list[int]:
        self.reads.append((address, count))
        return self.sim.read(address, count)

    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True) -> None:
        self.sim.write(address, values)

    def close(self) -> None:
        pass


@pytest.mark.parametrize("profile_id", ["dsx7e", "sd25", "is620p", "sdc"])
def test_reading_every_parameter_is_coalesced_within_the_drive_limit(sim_dir, profile_id):
    profile = load_profile(profile_id)
    link = CountingLink(build_drive(profile, 1, persist=False))
    params = [e for e in profile.of_class("Pn") if e.readable]
    readings = Drive(link, profile, 1).read(*[e.code for e in params])
    assert [r.entry.code for r in readings] == [e.code for e in params]
    assert all(count <= profile.limits.max_read for _, count in link.reads)
    assert len(link.reads) == len(coalesce_reads(profile, params))
    # Coalescing happened: far fewer requests than entries (SD25's 10-register limit still groups a few).
    assert len(link.reads) * 2 < len(params)


def test_a_modbus_exception_names_the_entry_and_the_exception(cli, sim_dir):
    build_drive(load_profile("dsx7e"), 1).inject_fault("Pn101", 4)
    r = cli("--port", "sim", "param", "set", "Pn101=30")
    assert r.code == 1 and len(r.err.strip().splitlines()) == 2  # the SIMULATED notice and the error
    assert "Pn101" in r.err and "Modbus exception 04 (slave device failure)" in r.err


def _garbling_proxy(target_port: int) -> int:
    """A TCP relay to the simulated drive that flips the last byte of every reply: a CRC error on the wire."""
    listener = socket.create_server(("127.0.0.1", 0))

    def pump(src: socket.socket, dst: socket.socket, garble: bool) -> None:
        while data := src.recv(512):
            dst.sendall(data[:-1] + bytes([data[-1] ^ 0xFF]) if garble else data)

    def accept() -> None:
        client, _ = listener.accept()
        upstream = socket.create_connection(("127.0.0.1", target_port))
        threading.Thread(target=pump, args=(client, upstream, False), daemon=True).start()
        pump(upstream, client, True)

    threading.Thread(target=accept, daemon=True).start()
    return listener.getsockname()[1]


def test_a_crc_error_is_reported_as_a_garbled_response_not_as_silence(cli, sim_dir):
    sim = EmbeddedSim([build_drive(load_profile("dsx7e"), 1, persist=False)])
    try:
        port = _garbling_proxy(int(sim.port.rsplit(":", 1)[1]))
        r = cli(
            "--port",
            f"tcp://127.0.0.1:{port}",
            "-P",
            "dsx7e",
            "--timeout",
            "0.3",
            "--retries",
            "0",
            "--no-identity-check",
            "param",
            "get",
            "Pn004",
        )
    finally:
        sim.close()
    assert r.code == 1 and len(r.err.strip().splitlines()) == 1
    assert "reading Pn004" in r.err and "garbled response" in r.err and "bad CRC" in r.err


def test_silence_is_reported_as_no_response(sim_dir):
    sim = EmbeddedSim([build_drive(load_profile("dsx7e"), 1, persist=False)])
    try:
        from servotool.link.master import RtuMaster
        from servotool.link.ports import LinkSettings

        link = RtuMaster(LinkSettings(port=sim.port, timeout=0.2, retries=0))
        with pytest.raises(DeviceError, match=r"no response within 0.2 s after 1 try \(wrong unit id"):
            link.read(9, 0x2004, 1)
        link.close()
    finally:
        sim.close()


class StaleOnceLink(CountingLink):
    """A link whose first read after a write answers with the register's value before the write: a stray reply
    that slipped through during a read-back."""

    def __init__(self, sim) -> None:
        super().__init__(sim)
        self.stale: dict[int, list[int]] = {}

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0)) -> list[int]:
        if (old := self.stale.pop(address, None)) is not None:
            self.reads.append((address, count))
            return old
        return super().read(unit, address, count)

    ignore = False  # acknowledge writes but make none

    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True) -> None:
        self.stale[address] = self.sim.read(address, len(values))
        if not self.ignore:
            super().write(unit, address, values, multiple=multiple)


def test_a_read_back_that_disagrees_is_read_again_before_it_is_reported(sim_dir):
    profile = load_profile("dsx7e")
    sim = build_drive(profile, 1, persist=False)
    link = StaleOnceLink(sim)
    drive = Drive(link, profile, 1)
    entry = profile.entry("Pn101")
    assert drive.write_verified(entry, 225).new == 225  # the stale 180 read back first, then 225
    assert link.reads == [(entry.address, 1), (entry.address, 1)]
    items = [(profile.entry("Pn101"), 230, None), (profile.entry("Pn102"), 320, None)]
    assert [r.new for r in drive.write_block_verified(items)] == [230, 320]
    link.ignore, link.reads = True, []  # a drive that ignores the write reads back its old value twice: reported
    with pytest.raises(VerifyError, match=r"Pn101: wrote 23\.5 but the drive reads back 23\.0"):
        drive.write_verified(entry, 235)
    assert link.reads == [(entry.address, 1), (entry.address, 1)]
