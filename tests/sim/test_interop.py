"""Interop: `servotool sim serve` on one end of a socat pty pair, a third-party master (mbpoll/libmodbus)
and servotool's own client on the other end."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(
    not (shutil.which("socat") and shutil.which("mbpoll")), reason="needs socat and mbpoll (installed by .ci/run)"
)

ROOT = Path(__file__).resolve().parents[2]


def _wait_for(path: Path, seconds: float = 5) -> None:
    end = time.monotonic() + seconds
    while not path.exists():
        if time.monotonic() > end:
            raise TimeoutError(path)
        time.sleep(0.05)


@pytest.fixture
def pty_line(tmp_path, sim_dir):
    """(drive side, master side) of a pty pair with two simulated drives (units 1 and 2) serving."""
    a, b = tmp_path / "drive", tmp_path / "master"
    socat = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"], stderr=subprocess.DEVNULL
    )
    _wait_for(a)
    _wait_for(b)
    server = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "sim",
            "serve",
            "--port",
            str(a),
            "--baud",
            "19200",
            "--unit",
            "1",
            "--unit",
            "2",
        ],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ),
    )
    line = server.stderr.readline()
    assert "serving on" in line, line
    yield a, b
    server.terminate()
    server.wait(timeout=10)
    socat.terminate()
    socat.wait(timeout=10)


def read(port: Path, ref: int, count: int = 1, unit: int = 1) -> list[int]:
    proc = subprocess.run(
        [
            "mbpoll",
            "-m",
            "rtu",
            "-a",
            str(unit),
            "-b",
            "19200",
            "-P",
            "none",
            "-t",
            "4",
            "-0",
            "-1",
            "-o",
            "1",
            "-r",
            str(ref),
            "-c",
            str(count),
            str(port),
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return [int(ln.split(":")[1]) for ln in proc.stdout.splitlines() if ln.startswith("[")]


def write(port: Path, ref: int, *values: int, unit: int = 1) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            "mbpoll",
            "-m",
            "rtu",
            "-a",
            str(unit),
            "-b",
            "19200",
            "-P",
            "none",
            "-t",
            "4",
            "-0",
            "-1",
            "-o",
            "1",
            "-r",
            str(ref),
            str(port),
            *map(str, values),
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )


def test_mbpoll_reads_and_writes_documented_addresses(pty_line):
    _, master = pty_line
    assert read(master, 0x2004) == [250]  # Pn004 load inertia ratio default
    assert read(master, 0x2008, 2) == [10000, 0]  # Pn008 u32, low word first
    assert read(master, 0x2100, 3) == [320, 180, 310]  # Pn100..Pn102 in one request
    ok = write(master, 0x2004, 300)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert read(master, 0x2004) == [300]
    assert read(master, 0x2004, unit=2) == [250]  # the second drive on the line is separate
    two = write(master, 0x2008, 20000, 0)  # FC16 over both words
    assert two.returncode == 0
    assert read(master, 0x2008, 2) == [20000, 0]


def test_mbpoll_gets_exception_responses(pty_line):
    _, master = pty_line
    out_of_range = write(master, 0x2004, 50)  # Pn004 min is 100
    assert out_of_range.returncode != 0 and "Illegal data value" in out_of_range.stderr
    unmapped = subprocess.run(
        [
            "mbpoll",
            "-m",
            "rtu",
            "-a",
            "1",
            "-b",
            "19200",
            "-P",
            "none",
            "-t",
            "4",
            "-0",
            "-1",
            "-o",
            "1",
            "-r",
            "100",
            "-c",
            "1",
            str(master),
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert unmapped.returncode != 0 and "Illegal data address" in unmapped.stderr
    read_only = write(master, 0x4000, 5)  # Un000 motor speed
    assert read_only.returncode != 0 and "Illegal data address" in read_only.stderr
    assert read(master, 0x2004) == [250]  # nothing changed


def test_servotool_client_over_the_same_line(pty_line, cli):
    _, master = pty_line
    base = ("--port", str(master), "--baud", "19200", "--profile", "dsx7e")
    r = cli(*base, "param", "set", "Pn101=22.5")
    assert r.code == 0, r.err
    assert read(master, 0x2101) == [225]
    r = cli(*base, "--unit", "2", "param", "get", "Pn101", "--json")
    assert r.code == 0 and r.json()[0]["value"] == 18.0
    r = cli(*base, "--unit", "7", "--timeout", "0.2", "--retries", "0", "param", "get", "Pn101")
    assert r.code == 1 and "no response within" in r.err


# ----- the Modbus specification, as libmodbus (mbpoll's library) exercises it ---------------------------------------
def _libmodbus(port: Path):
    """A libmodbus RTU context on the master side (ctypes; libmodbus.so.5 comes with mbpoll)."""
    import ctypes
    import ctypes.util

    lib = ctypes.CDLL(ctypes.util.find_library("modbus") or "libmodbus.so.5", use_errno=True)
    lib.modbus_new_rtu.restype = ctypes.c_void_p
    lib.modbus_new_rtu.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char, ctypes.c_int, ctypes.c_int]
    for name in (
        "modbus_set_slave",
        "modbus_connect",
        "modbus_write_register",
        "modbus_send_raw_request",
        "modbus_receive_confirmation",
        "modbus_set_response_timeout",
        "modbus_close",
        "modbus_free",
    ):
        getattr(lib, name).argtypes = [
            ctypes.c_void_p,
            *{
                "modbus_set_slave": [ctypes.c_int],
                "modbus_write_register": [ctypes.c_int, ctypes.c_uint16],
                "modbus_send_raw_request": [ctypes.c_char_p, ctypes.c_int],
                "modbus_receive_confirmation": [ctypes.c_char_p],
                "modbus_set_response_timeout": [ctypes.c_uint32, ctypes.c_uint32],
            }.get(name, []),
        ]
    ctx = lib.modbus_new_rtu(str(port).encode(), 19200, b"N", 8, 1)
    assert ctx and lib.modbus_connect(ctx) == 0
    lib.modbus_set_response_timeout(ctx, 0, 300_000)
    return lib, ctx


def _raw_exchange(lib, ctx, unit: int, pdu: bytes) -> bytes:
    """Send one request PDU through libmodbus (it adds the unit and CRC); the reply frame it receives."""
    import ctypes

    lib.modbus_set_slave(ctx, unit)
    req = bytes([unit]) + pdu
    assert lib.modbus_send_raw_request(ctx, req, len(req)) > 0
    buf = ctypes.create_string_buffer(260)
    n = lib.modbus_receive_confirmation(ctx, buf)
    return buf.raw[: max(n, 0)]


def test_libmodbus_broadcast_write_is_applied_by_every_drive_and_unanswered(pty_line):
    _, master = pty_line
    lib, ctx = _libmodbus(master)
    try:
        lib.modbus_set_slave(ctx, 0)
        lib.modbus_write_register(ctx, 0x2004, 321)  # Pn004 on unit 0: every drive on the line
        # The reply to a broadcast would be a frame from unit 0: nothing may come back.
        assert _raw_exchange(lib, ctx, 0, bytes([6, 0x20, 0x04, 0x01, 0x41])) == b""
    finally:
        lib.modbus_close(ctx)
        lib.modbus_free(ctx)
    assert read(master, 0x2004, unit=1) == [321]
    assert read(master, 0x2004, unit=2) == [321]


SPEC_EXCEPTIONS = [
    (bytes([3, 0x20, 0x04, 0, 0]), 3),  # read 0 registers
    (bytes([3, 0x20, 0x04, 0, 126]), 3),  # read 126
    (bytes([4, 0x20, 0x04, 0, 1]), 1),  # FC04: no manual lists it
    (bytes([16, 0x20, 0x04, 0, 0, 0]), 3),  # write 0 registers
    (bytes([16, 0x20, 0x04, 0, 124, 2, 0, 1]), 3),  # write 124 (an RTU frame cannot carry them all)
    (bytes([1, 0, 100, 0, 1]), 1),  # read coils: unsupported, at an unmapped address
    (bytes([5, 0x20, 0x04, 0xFF, 0]), 1),  # write coil at a mapped address
    (bytes([23, 0x20, 0x04, 0, 1, 0x20, 0x04, 0, 1, 2, 0, 5]), 1),  # read/write multiple
]


def test_libmodbus_gets_the_specified_exceptions(pty_line):
    _, master = pty_line
    lib, ctx = _libmodbus(master)
    try:
        replies = [(_raw_exchange(lib, ctx, 1, pdu), pdu, code) for pdu, code in SPEC_EXCEPTIONS]
    finally:
        lib.modbus_close(ctx)
        lib.modbus_free(ctx)
    for reply, pdu, code in replies:
        assert reply[:3] == bytes([1, pdu[0] | 0x80, code]), (pdu.hex(" "), reply.hex(" "))


def test_mbpoll_unsupported_function_is_illegal_function_at_any_address(pty_line):
    _, master = pty_line
    for ref in ("100", str(0x2004)):  # unmapped and mapped
        coils = subprocess.run(
            [
                "mbpoll",
                "-m",
                "rtu",
                "-a",
                "1",
                "-b",
                "19200",
                "-P",
                "none",
                "-t",
                "0",
                "-0",
                "-1",
                "-o",
                "1",
                "-r",
                ref,
                str(master),
            ],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert coils.returncode != 0 and "Illegal function" in coils.stderr, coils.stderr


# ----- Modbus over Serial Line 2.5.1.1: a frame ends at the 3.5-character silence ---------------------------------
def test_an_incomplete_frame_is_dropped_at_the_silence_and_the_next_request_answered(pty_line):
    import serial

    from servotool.link.crc import with_crc

    _, master = pty_line
    request = with_crc(bytes([1, 3, 0x20, 0x04, 0, 1]))  # Pn004
    with serial.Serial(str(master), 19200, timeout=0.3) as port:
        port.write(request[:5])  # cut short; the silence after it ends it
        assert port.read(16) == b""  # nothing answers an incomplete frame
        port.write(request)
        assert port.read(7) == with_crc(bytes([1, 3, 2, 0, 250]))  # and the next request is not swallowed
    assert read(master, 0x2004) == [250]


def test_an_fc16_whose_byte_count_disagrees_with_its_data_gets_exception_03(pty_line):
    _, master = pty_line
    lib, ctx = _libmodbus(master)
    try:
        # Byte count 4 for one register, 2 data bytes, a valid CRC: the silence ends it 2 bytes early.
        short = _raw_exchange(lib, ctx, 1, bytes([16, 0x20, 0x04, 0, 1, 4, 0x01, 0x2C]))
        # Byte count 2 for two registers.
        inconsistent = _raw_exchange(lib, ctx, 1, bytes([16, 0x20, 0x04, 0, 2, 2, 0x01, 0x2C]))
    finally:
        lib.modbus_close(ctx)
        lib.modbus_free(ctx)
    assert short[:3] == bytes([1, 0x90, 3]), short.hex(" ")
    assert inconsistent[:3] == bytes([1, 0x90, 3]), inconsistent.hex(" ")
    assert read(master, 0x2004) == [250]  # nothing written, and the next request answered


def test_raw_read_agrees_with_mbpoll(pty_line, cli):
    _, master = pty_line
    r = cli("--port", str(master), "--baud", "19200", "--profile", "dsx7e", "raw", "read", "0x2100", "3", "--json")
    assert r.code == 0, r.err
    assert [x["value"] for x in r.json()] == read(master, 0x2100, 3)
