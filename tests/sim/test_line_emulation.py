"""The simulated drive answers at its line's pace by default (issue 33 item 3): each reply comes after the wire time
of its request and itself at the profile's factory speed and character format, unless the drive's `sim config
--line-baud` or SERVOTOOL_SIM_LINE_BAUD says fast (or another speed); the banner says which."""

from __future__ import annotations

import socket
import statistics
import time

import pytest

from servotool.link.rtu import with_crc
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings
from servotool.sim.firmware import build_drive
from servotool.sim.line import Emulated, emulated
from servotool.sim.server import EmbeddedSim

READ_N = 20  # registers: a long reply, so that a loaded machine's scheduling is small beside its wire time


def _exchange_seconds(port: str, frame: bytes, tries: int = 5) -> list[float]:
    """Seconds from sending a request to the whole reply, over the simulator's socket, each try."""
    host, _, number = port.removeprefix("tcp://").rpartition(":")
    took = []
    with socket.create_connection((host, int(number)), timeout=5) as sock:
        for _ in range(tries):
            start = time.perf_counter()
            sock.sendall(frame)
            reply = b""
            while len(reply) < 5 + 2 * READ_N:
                reply += sock.recv(512)
            took.append(time.perf_counter() - start)
    return took


def _readable_run(profile_id: str) -> int:
    """The first address where READ_N registers in a row are all mapped."""
    p = load_profile(profile_id)
    mapped = {a for e in p.entries if e.readable for a in e.addresses}
    return next(a for a in sorted(mapped) if all(a + i in mapped for i in range(READ_N)))


@pytest.mark.parametrize(("line", "bits"), [(LineSettings(9600, "N", 1), 10), (LineSettings(9600, "E", 1), 11)])
def test_a_character_takes_start_data_parity_and_stop_bits(line, bits):
    timed = Emulated(line)
    assert timed.bits == bits
    # a 1-register read: 8 request and 7 reply characters, 3.5 characters of silence after each
    assert timed.seconds(3, 1) == pytest.approx((8 + 7 + 7) * bits / 9600)


def test_which_line_a_drive_is_timed_by(factory_line):
    """The connection's line (the profile's factory one unless given); the drive's own setting over the
    environment's default; sim serve's choice over both; on a serial port 'factory' adds nothing."""
    sd25 = build_drive(load_profile("sd25"), 1, persist=False)
    even = LineSettings(9600, "E", 1)
    assert emulated(sd25, None).describe() == "9600 baud 8N1"  # SD25's factory line
    assert emulated(sd25, even).describe() == "9600 baud 8E1"
    assert emulated(sd25, None, default="fast") is None
    assert emulated(sd25, None, wired=True) is None
    assert emulated(sd25, even, 19200).describe() == "19200 baud 8E1"  # a speed keeps the line's format
    sd25.settings["line_baud"] = 38400
    assert emulated(sd25, None, default="fast").describe() == "38400 baud 8N1"
    sd25.settings["line_baud"] = "fast"
    assert emulated(sd25, None) is None
    assert emulated(sd25, None, "factory").describe() == "9600 baud 8N1"


def test_an_exchange_takes_its_wire_time_on_the_line_the_connection_uses(factory_line):
    """At 9600 baud 8E1 a 20-register read is (8 + 45 + 7) characters of 11 bits, 68.75 ms; without the emulation
    the same exchange is a loopback round trip. The emulated time cannot come early (the reply waits that long);
    the fast one is held to under half of it, which a busy 2-core machine keeps by far."""
    p = load_profile("dsx7e")
    address = _readable_run("dsx7e")
    frame = with_crc(bytes([1, 3]) + address.to_bytes(2, "big") + READ_N.to_bytes(2, "big"))
    line = LineSettings(9600, "E", 1)
    wire = Emulated(line).seconds(3, READ_N)
    assert wire == pytest.approx(0.06875)
    sim = EmbeddedSim([build_drive(p, 1)], line=line)
    try:
        assert sim.line.describe() == "line emulated at 9600 baud 8E1"
        slow = _exchange_seconds(sim.port, frame)
    finally:
        sim.close()
    fast_drive = build_drive(p, 1)
    fast_drive.configure(line_baud="fast")
    sim = EmbeddedSim([fast_drive], line=line)
    try:
        assert sim.line.describe() == "line NOT emulated: fast"
        fast = _exchange_seconds(sim.port, frame)
    finally:
        sim.close()
    early = max(0.002, time.get_clock_info("monotonic").resolution)  # asyncio wakes within its clock's resolution
    assert min(slow) >= wire - early, slow
    assert statistics.median(fast) < wire / 2, fast


def test_by_default_each_profile_answers_at_its_factory_line(factory_line):
    """No line given: each drive is timed by its profile's factory settings (SD25 9600 8N1, DSX7E 115200 8N1)."""
    drives = [build_drive(load_profile(pid), u, persist=False) for u, pid in ((1, "sd25"), (2, "dsx7e"))]
    sim = EmbeddedSim(drives)
    try:
        assert sim.line.describe() == "unit 1: line emulated at 9600 baud 8N1; unit 2: line emulated at 115200 baud 8N1"
    finally:
        sim.close()


def test_the_banner_says_whether_the_line_is_emulated(cli, factory_line):
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po001")
    assert r.code == 0, r.err
    assert "SIMULATED drive sd25 unit 1, line emulated at 9600 baud 8N1" in r.err
    r = cli("--port", "sim", "-P", "sd25", "--parity", "E", "param", "get", "Po001")
    assert "line emulated at 9600 baud 8E1" in r.err  # the line the connection uses
    assert cli("sim", "config", "-P", "sd25", "--line-baud", "fast").code == 0
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po001")
    assert r.code == 0 and "line NOT emulated: fast" in r.err
    r = cli("--port", "sim", "-P", "sdc", "param", "get", "PN1", env={"SERVOTOOL_SIM_LINE_BAUD": "19200"})
    assert r.code == 0 and "line emulated at 19200 baud 8O1" in r.err
    for line in r.err.splitlines():
        assert len(line) <= 80, line


def test_a_bad_line_choice_is_refused_in_one_line(cli):
    r = cli("sim", "config", "--line-baud", "quick")
    assert r.code == 2 and "factory, fast or 300..10000000" in r.err and len(r.err.splitlines()) == 1
    r = cli("--port", "sim", "param", "get", "Pn004", env={"SERVOTOOL_SIM_LINE_BAUD": "12"})
    assert r.code == 2 and "SERVOTOOL_SIM_LINE_BAUD" in r.err


def test_sim_show_says_what_the_drive_is_timed_by(cli, factory_line):
    shown = cli("sim", "show", "-P", "sd25", "--json").json()["settings"]
    assert shown["line_baud"] == "factory"
    assert cli("sim", "config", "-P", "sd25", "--line-baud", "0").code == 0  # 0: off, as it always meant
    assert cli("sim", "show", "-P", "sd25", "--json").json()["settings"]["line_baud"] == "fast"
    assert cli("sim", "config", "-P", "sd25", "--line-baud", "19200").code == 0
    assert cli("sim", "show", "-P", "sd25", "--json").json()["settings"]["line_baud"] == 19200


def test_a_baud_entry_changes_the_line_after_its_own_reply(factory_line):
    """SD25's Po504 takes effect at once (manual 6.2.4): the write that changes it is answered at the old speed,
    every later answer comes at the new one; its factory code leaves the line as the connection has it."""
    from servotool.sim.line import Line

    sd25 = build_drive(load_profile("sd25"), 1, persist=False)
    line = Line([sd25])
    _regs, took = line.serve(sd25, 6, 504, 1, [5])  # Po504 = 5 (57600)
    assert took == pytest.approx(Emulated(LineSettings(9600)).seconds(6, 1))
    _regs, took = line.serve(sd25, 3, 504, 1, None)
    assert took == pytest.approx(Emulated(LineSettings(57600)).seconds(3, 1))
    assert line.describe() == "line emulated at 57600 baud 8N1"
    line.host = LineSettings(9600)  # a master still at 9600 is not heard ...
    assert line.serve(sd25, 3, 504, 1, None) == (None, 0.0)
    line.host = LineSettings(57600)  # ... one at 57600 is
    assert line.serve(sd25, 6, 504, 1, [2])[0] == []
    assert line.describe() == "line emulated at 9600 baud 8N1"
