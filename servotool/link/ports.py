"""Port specs and line settings, and the Link protocol drive operations use. No pymodbus here: the simulator
imports this module and must stand without the client."""

from __future__ import annotations

import errno
import os
import re
import socket
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from servotool.errors import DeviceError, UsageError
from servotool.model.profile import LineSettings

if TYPE_CHECKING:  # pyserial's platform module (serialposix imports termios) loads only when a port opens
    import serial

Trace = Callable[[bool, bytes], None]


@dataclass(frozen=True)
class LinkSettings:
    """Where and how to talk to a drive."""

    port: str
    line: LineSettings = field(default_factory=LineSettings)
    timeout: float = 1.0
    retries: int = 2
    echo: bool | None = False  # the adapter echoes what it sends (None: find out from the first replies)
    turnaround: float = 0.0  # s of quiet after a reply before the next request (slow drives' transceivers)
    silence: float | None = None  # s of quiet that ends a frame; None: RTU's 3.5 characters at the baud rate
    heartbeat: str | None = None  # dtr or rts: a control line kept low at open and toggled by the heartbeat


class Link(Protocol):
    """What drive operations need from a Modbus master."""

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0), fc: int = 3) -> list[int]:
        """`count` registers at `address` (fc 3 holding, 4 input registers). spare = registers before and after that
        may be read as well (whole readable entries): a master without transaction ids reads them to tell its
        replies apart."""
        ...

    def write(
        self,
        unit: int,
        address: int,
        values: list[int],
        *,
        multiple: bool = True,
        idempotent: bool = True,
        coils: bool = False,
    ) -> None:
        """Write registers (with `coils`, bits 0/1: FC05/FC15). idempotent=False (an Fn trigger) means a write
        whose fate is unknown is never sent again; an idempotent one may be."""
        ...

    def close(self) -> None: ...


_TCP_RE = re.compile(r"^tcp://(?P<host>\[[^\]]+\]|[^:/]+):(?P<port>\d+)$")


def parse_tcp(port: str) -> tuple[str, int] | None:
    """(host, port) of a tcp://host:port spec, None for other specs; UsageError when malformed."""
    if not port.startswith("tcp://"):
        return None
    m = _TCP_RE.match(port)
    if not m or not 0 <= int(m["port"]) < 65536:
        raise UsageError(f"bad port '{port}': expected tcp://HOST:PORT")
    return m["host"].strip("[]"), int(m["port"])


SERIAL_BY_ID = Path("/dev/serial/by-id")


def bus_identity(port: str, by_id: Path = SERIAL_BY_ID) -> str:
    """The one name of the bus a port spec reaches, whatever its spelling, for the host's journal and write lock:
    a serial device by its /dev/serial/by-id link where one points to it (stable across a replug), else by its
    real path (macOS's /dev/tty.X as /dev/cu.X, the same device); a COM port by its upper-case name (Windows has
    no realpath for it); tcp://HOST:PORT by the address HOST resolves to, every loopback address as localhost."""
    tcp = parse_tcp(port)
    if tcp is not None:
        return f"tcp://{_host_identity(tcp[0])}:{tcp[1]}"
    com = re.fullmatch(r"(?:\\\\[.?]\\)?(COM\d+)", port, re.IGNORECASE)
    if com or sys.platform.startswith("win"):
        return com[1].upper() if com else port
    real = os.path.realpath(port)
    try:
        links = sorted(by_id.iterdir())
    except OSError:
        links = []
    for link in links:
        if os.path.realpath(link) == real:
            return str(link)
    return re.sub(r"^/dev/tty\.", "/dev/cu.", real)


def _host_identity(host: str) -> str:
    """The address a host name resolves to (the first IPv4 one, else the first); 'localhost' for any loopback
    address; the name itself, in lower case, when it does not resolve."""
    import ipaddress

    try:
        infos = socket.getaddrinfo(host.encode() if host.isascii() else host, None, type=socket.SOCK_STREAM)
        found = [ipaddress.ip_address(str(info[4][0]).split("%")[0]) for info in infos]
    except (OSError, UnicodeError, ValueError):
        return host.lower()
    mapped = [a.ipv4_mapped or a if isinstance(a, ipaddress.IPv6Address) else a for a in found]
    if not mapped:
        return host.lower()
    if any(a.is_loopback for a in mapped):
        return "localhost"
    return str(next((a for a in mapped if a.version == 4), mapped[0]))


# ----- opening a port, and why it would not open --------------------------------------------------------------
PARITY_NAMES = {"N": "none", "E": "even", "O": "odd"}
SYSFS_USB_SERIAL = Path("/sys/bus/usb-serial/devices")


def open_serial(
    port: str, line: LineSettings, timeout: float, low: str | None = None, doing: str = "open port"
) -> serial.Serial:
    """Open and configure a serial port for exclusive use; DeviceError naming the real cause when it will not
    ('cannot {doing} {port}: ...'). low: a control line (dtr, rts) held low from the moment the port opens (a
    heartbeat's resting level)."""
    import serial

    try:
        s = serial.Serial(
            None,
            baudrate=line.baud,
            bytesize=line.bytesize,
            parity=line.parity,
            stopbits=line.stopbits,
            timeout=timeout,
            exclusive=True,
        )
        if low is not None:
            setattr(s, low, False)  # pyserial applies it as the port opens: no pulse before the first beat
        s.port = port
        s.open()
        return s
    except Exception as exc:  # SerialException, OSError, termios.error (not an OSError), ValueError
        raise DeviceError(f"cannot {doing} {port}: {port_problem(port, exc, line)}") from None


class ControlLine:
    """One modem control line (DTR or RTS) of an open serial port, set high or low: what a heartbeat toggles."""

    def __init__(self, port: serial.SerialBase, name: str) -> None:
        self.port, self.name = port, name
        self.level = False

    def set(self, level: bool) -> None:
        setattr(self.port, self.name, level)
        self.level = level


def open_tcp(port: str, timeout: float) -> socket.socket:
    """Connect to a tcp://HOST:PORT spec; DeviceError naming the real cause when it cannot."""
    host, number = parse_tcp(port) or ("", 0)
    try:
        # An ASCII name goes as bytes: as text, getaddrinfo loads the IDNA codec (2 ms) to leave it unchanged.
        sock = socket.create_connection((host.encode() if host.isascii() else host, number), timeout=timeout)
    except OSError as exc:
        raise DeviceError(f"cannot open port {port}: {port_problem(port, exc, timeout=timeout)}") from None
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def _errno(exc: BaseException) -> int | None:
    """The OS error number behind an exception, also where pyserial or termios only put it in the text."""
    for value in (getattr(exc, "errno", None), *(exc.args[:1] if exc.args else ())):
        if isinstance(value, int):
            return value
    m = re.search(r"(?:Errno |\()(\d+)[\],]", str(exc))
    return int(m[1]) if m else None


def port_problem(port: str, exc: BaseException, line: LineSettings | None = None, timeout: float | None = None) -> str:
    """The cause of a failure to open (or serve on) a port, in words: not found, busy, permission denied, not a
    serial device, a setting the port cannot do, DNS failure, refused, unreachable, timeout. The one
    classification used by the client and the simulator's server."""
    tcp = parse_tcp(port) if port.startswith("tcp://") else None
    where = f"{tcp[0]}:{tcp[1]}" if tcp else port
    text, code = str(exc), _errno(exc)
    if isinstance(exc, socket.gaierror) or (code is not None and code < 0):  # getaddrinfo's EAI_* codes
        why = exc.strerror if isinstance(exc, socket.gaierror) else text
        return f"host name '{tcp[0] if tcp else port}' not found (DNS lookup failed: {why})"
    if isinstance(exc, ConnectionRefusedError) or code == errno.ECONNREFUSED:
        return f"connection refused: nothing listens on {where}"
    if isinstance(exc, TimeoutError) or code == errno.ETIMEDOUT:
        return f"no answer from {where}" + (f" within {timeout:g} s" if timeout else "") + " (host down or filtered)"
    if code in (errno.EHOSTUNREACH, errno.ENETUNREACH):
        return f"{where} is unreachable (no route to the host or network)"
    if code == errno.EADDRINUSE:
        return f"{where} is in use by another program"
    if code == errno.ENOENT or "FileNotFoundError" in text or "cannot find the file" in text:
        return "not found: no such device (is the adapter plugged in? see /dev/serial/by-id or the device list)"
    if code in (errno.EBUSY, errno.EAGAIN) or "exclusively lock" in text:
        return "busy: another program has the port open"
    if code in (errno.EACCES, errno.EPERM) or "PermissionError" in text or "Access is denied" in text:
        if sys.platform.startswith("win"):
            return "busy or access denied: another program may have the port open"
        return "permission denied (on Linux, join the port's group: sudo usermod -aG dialout $USER, then log in again)"
    if code == errno.ENOTTY or "Inappropriate ioctl" in text:
        return "not a serial device"
    if code == errno.EINVAL and line is not None:
        if line.parity != "N":
            return (
                f"the port cannot do parity {line.parity} ({PARITY_NAMES[line.parity]}) (a pty or some adapters "
                f"have no parity): set --parity N on both ends, or use a real serial port"
            )
        return f"the port cannot do {line.describe()} (baud rate, data or stop bits)"
    return text or type(exc).__name__


def usb_latency_ms(port: str, sysfs: Path = SYSFS_USB_SERIAL) -> int | None:
    """A USB-serial adapter's latency timer (ms it holds received bytes before passing them on), or None where
    there is none to read (not Linux, not a ttyUSB/ttyACM port, no such file)."""
    if not sys.platform.startswith("linux") or port.startswith("tcp://"):
        return None
    try:
        name = os.path.basename(os.path.realpath(port))
        if not re.fullmatch(r"tty(USB|ACM)\d+", name):
            return None
        return int((sysfs / name / "latency_timer").read_text().strip())
    except (OSError, ValueError):
        return None


def latency_advice(port: str, sysfs: Path = SYSFS_USB_SERIAL) -> str | None:
    """When a USB adapter's latency timer above 1 ms caps the request rate: by how much, and how to lower it."""
    ms = usb_latency_ms(port, sysfs)
    if ms is None or ms <= 1:
        return None
    path = sysfs / os.path.basename(os.path.realpath(port)) / "latency_timer"
    return (
        f"{port}: the USB adapter holds received bytes up to {ms} ms (latency_timer), so every reply waits and "
        f"the link makes at most about {1000 // ms} requests/s; lower it with 'echo 1 | sudo tee {path}' (until "
        f'unplugged) or for good with a udev rule: ACTION=="add", SUBSYSTEM=="usb-serial", '
        f'DRIVER=="ftdi_sio", ATTR{{latency_timer}}="1"'
    )
