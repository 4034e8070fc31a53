"""Opening a port: every failure names its real cause, on the client and in `sim serve`; RS485 habits (echo,
turnaround, silence) reach the link; a slow USB adapter's latency timer is pointed out."""

from __future__ import annotations

import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from servotool.connection import ConnectOptions, resolve
from servotool.errors import DeviceError, UsageError
from servotool.link.crc import with_crc
from servotool.link.exchange import Exchange
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings, latency_advice, open_serial, usb_latency_ms
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings
from servotool.sim.faults import LineFaults
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim

ROOT = Path(__file__).resolve().parents[2]
needs_socat = pytest.mark.skipif(not shutil.which("socat"), reason="needs socat (installed by .ci/run)")


def refused_port() -> int:
    """A local TCP port where nothing listens (bound, never listening)."""
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    refused_port.keep = s  # type: ignore[attr-defined]   # held until the next call
    return s.getsockname()[1]


@pytest.mark.parametrize(
    ("port", "cause"),
    [
        ("/dev/ttyNOPE7", "not found: no such device"),
        ("{file}", "not a serial device"),
        ("tcp://no-such-host.invalid:502", "host name 'no-such-host.invalid' not found (DNS lookup failed"),
        ("tcp://127.0.0.1:{refused}", "connection refused: nothing listens on 127.0.0.1:"),
    ],
)
def test_a_port_that_will_not_open_names_the_cause(cli, tmp_path, port, cause):
    regular = tmp_path / "not-a-tty"
    regular.write_text("x")
    spec = port.format(file=regular, refused=refused_port() if "refused" in port else 0)
    r = cli("--port", spec, "-P", "sd25", "param", "get", "Po001")
    assert r.code == 1 and r.err.count("\n") == 1, r.err
    assert f"cannot open port {spec}: {cause}" in r.err, r.err


def test_sim_serve_names_why_it_cannot_listen(cli):
    taken = socket.create_server(("127.0.0.1", 0))
    try:
        where = f"127.0.0.1:{taken.getsockname()[1]}"
        r = cli("sim", "serve", "--port", f"tcp://{where}", timeout=30)
        assert r.code == 1 and f"cannot serve on tcp://{where}: {where} is in use by another program" in r.err, r.err
    finally:
        taken.close()
    r = cli("sim", "serve", "--port", "tcp://no-such-host.invalid:5020", timeout=30)
    assert r.code == 1 and "host name 'no-such-host.invalid' not found (DNS lookup failed" in r.err, r.err


@pytest.fixture
def pty_pair(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    socat = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"], stderr=subprocess.DEVNULL
    )
    end = time.monotonic() + 5
    while not (a.exists() and b.exists()) and time.monotonic() < end:
        time.sleep(0.02)
    yield a, b
    socat.terminate()
    socat.wait(timeout=10)


@needs_socat
def test_parity_a_pty_cannot_do_is_one_line_naming_it_on_client_and_server(cli, pty_pair):
    a, b = pty_pair
    # Linux refuses parity on a pty with EINVAL, though not on every open (a second open with the same parity
    # meets it when the first did not): open twice, and each refusal must name the setting.
    refusals = []
    for _ in range(2):
        try:
            open_serial(str(b), LineSettings(9600, "E"), 0.1).close()
        except DeviceError as exc:
            refusals.append(str(exc))
    assert refusals and all(f"cannot open port {b}: the port cannot do parity E (even)" in r for r in refusals)
    r = cli("sim", "serve", "-P", "sdc", "--port", str(a), timeout=30)
    assert r.code == 1 and r.err.count("\n") == 1 and "internal error" not in r.err, r.err
    assert f"cannot serve on {a}: the port cannot do parity O (odd)" in r.err, r.err


@needs_socat
def test_a_port_another_program_holds_is_busy(cli, pty_pair):
    import serial

    _, b = pty_pair
    with serial.Serial(str(b), 9600, exclusive=True):
        r = cli("--port", str(b), "-P", "dsx7e", "param", "get", "Pn004")
    assert r.code == 1 and f"cannot open port {b}: busy: another program has the port open" in r.err, r.err


def test_latency_timer_above_1ms_is_advised_with_the_fix(tmp_path):
    (tmp_path / "ttyUSB3").mkdir()
    (tmp_path / "ttyUSB3" / "latency_timer").write_text("16\n")
    if not sys.platform.startswith("linux"):
        assert usb_latency_ms("/dev/ttyUSB3", tmp_path) is None
        return
    assert usb_latency_ms("/dev/ttyUSB3", tmp_path) == 16
    advice = latency_advice("/dev/ttyUSB3", tmp_path)
    assert advice and "16 ms" in advice and "at most about 62 requests/s" in advice
    assert f"echo 1 | sudo tee {tmp_path}/ttyUSB3/latency_timer" in advice and "udev rule" in advice
    (tmp_path / "ttyUSB3" / "latency_timer").write_text("1\n")
    assert latency_advice("/dev/ttyUSB3", tmp_path) is None
    assert latency_advice("/dev/ttyUSB9", tmp_path) is None  # no such file: nothing
    assert latency_advice("/dev/ttyS0", tmp_path) is None  # not a USB adapter
    assert latency_advice("tcp://127.0.0.1:502", tmp_path) is None


def test_rs485_options_reach_the_link_settings(sim_dir, monkeypatch):
    s = resolve(ConnectOptions(port="sim", echo="on", turnaround_ms=5, silence_ms=2.5)).settings
    assert (s.echo, s.turnaround, s.silence) == (True, 0.005, 0.0025)
    assert resolve(ConnectOptions(port="sim")).settings.echo is None  # auto by default
    monkeypatch.setenv("SERVOTOOL_ECHO", "off")
    monkeypatch.setenv("SERVOTOOL_TURNAROUND_MS", "3")
    s = resolve(ConnectOptions(port="sim")).settings
    assert (s.echo, s.turnaround) == (False, 0.003)
    for bad in (ConnectOptions(port="sim", echo="maybe"), ConnectOptions(port="sim", silence_ms=-1)):
        with pytest.raises(UsageError):
            resolve(bad)


def test_bad_echo_option_is_a_usage_error(cli):
    r = cli("--port", "sim", "--echo", "sometimes", "param", "get", "Pn004")
    assert r.code == 2 and "bad echo 'sometimes': use auto, on or off" in r.err


def test_turnaround_keeps_the_line_quiet_after_each_reply():
    now = [0.0]
    sent_at: list[float] = []
    queued: list[bytes] = []

    class Line:
        def send(self, frame: bytes) -> None:
            sent_at.append(now[0])
            queued.append(with_crc(bytes([1, 3, 2, 0, 7])))

        def recv(self, timeout: float) -> bytes:
            if queued:
                now[0] += 0.001
                return queued.pop()
            now[0] += timeout
            return b""

    class Clock:
        def now(self) -> float:
            return now[0]

        def wall(self) -> float:
            return now[0]

        def sleep(self, s: float) -> None:
            now[0] += s

    ex = Exchange(Line(), timeout=0.1, retries=0, turnaround=0.02, clock=Clock())
    assert ex.read(1, 0, 1) == [7] and ex.read(1, 1, 1) == [7]
    assert sent_at[1] - sent_at[0] >= 0.021


@pytest.mark.parametrize("first", ["read", "write"])
def test_echo_auto_finds_an_echoing_adapter_on_the_first_exchange(sim_dir, first):
    profile = load_profile("dsx7e")
    sim = EmbeddedSim([build_drive(profile, 1, persist=False)], LineFaults(echo=True))
    try:
        link = RtuMaster(LinkSettings(sim.port, timeout=0.2, retries=1, echo=None))
        entry = profile.entry("Pn004")
        if first == "write":  # an FC06 reply repeats the request: a probe tells echo from reply
            link.write(1, entry.address, [300], multiple=False)
        assert link.read(1, entry.address, 1) == [300 if first == "write" else 250]
        assert link.echo is True
        link.close()
        # Told there is no echo, the link still knows its own requests when they come back: never a reply.
        seen: list[bytes] = []
        off = RtuMaster(
            LinkSettings(sim.port, timeout=0.1, retries=0, echo=False),
            trace=lambda s, d: seen.append(d) if not s else 0,
        )
        assert off.read(1, entry.address, 1) == [300 if first == "write" else 250]
        assert seen[0].startswith(bytes([1, 3]) + entry.address.to_bytes(2, "big") + bytes([0, 1]))  # its echo came
        off.close()
    finally:
        sim.close()
