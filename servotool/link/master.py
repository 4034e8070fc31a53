"""servotool's own RTU master: open a port (serial or RTU over TCP) and read/write registers over it, every reply
matched to its request by link/exchange.py. No pymodbus on this side: pymodbus serves only the simulated slave.

Everything else in servotool talks to `Link`, never to a port directly."""

from __future__ import annotations

import select
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING

from servotool.link.exchange import Exchange, Wire
from servotool.link.ports import ControlLine, LinkSettings, Trace, open_serial, open_tcp, parse_tcp
from servotool.model.profile import LineSettings

if TYPE_CHECKING:  # pyserial's platform module (serialposix imports fcntl) loads only with a real port
    import serial


class RtuMaster:
    """RTU frames over a serial line or a TCP socket; every exchange goes through `Exchange`, which accepts only
    replies that provably answer their request. The port is opened here (pyserial, socket) so that an error names
    its real cause (link.ports.port_problem)."""

    def __init__(self, settings: LinkSettings, trace: Trace | None = None) -> None:
        self.settings = settings
        self.line_listeners: list[Callable[[LineSettings], None]] = []  # told when set_line changes the speed
        tcp = parse_tcp(settings.port)
        self._port: socket.socket | serial.Serial
        wire: Wire
        if tcp:
            self._port = open_tcp(settings.port, settings.timeout)
            wire = _SocketWire(self._port)
        else:
            self._port = open_serial(settings.port, settings.line, settings.timeout, settings.heartbeat)
            wire = _SerialWire(self._port)
        silence = settings.silence if settings.silence is not None else 0.0 if tcp else _frame_gap(settings.line.baud)
        self._exchange = Exchange(
            wire,
            timeout=settings.timeout,
            retries=settings.retries,
            settle=silence,
            turnaround=settings.turnaround,
            echo=settings.echo,
            char_s=_char_time(settings.line),
            baud=settings.line.baud,
            trace=trace,
        )

    @property
    def requests(self) -> int:
        """Frames sent so far (tries and confirming reads included)."""
        return self._exchange.requests

    @property
    def echo(self) -> bool | None:
        """Whether the adapter echoes what it sends: as set, or as found out (None: not yet known)."""
        return self._exchange.echo

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0), fc: int = 3) -> list[int]:
        return self._exchange.read(unit, address, count, spare=spare, fc=fc)

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
        self._exchange.write(unit, address, values, multiple=multiple, idempotent=idempotent, coils=coils)

    def control_line(self) -> ControlLine | None:
        """The control line the settings name for a heartbeat (held low since the port opened), None without."""
        name = self.settings.heartbeat
        if name is None or parse_tcp(self.settings.port):
            return None
        return ControlLine(self._port, name)  # type: ignore[arg-type]

    @property
    def line(self) -> LineSettings:
        """The line settings the master speaks now."""
        return self.settings.line

    def set_line(self, line: LineSettings) -> None:
        """Speak at other line settings from the next request on (a drive whose baud entry changed it): the serial
        port's own settings, and the frame-ending silence that follows the baud rate; over tcp:// only the record
        (and the listeners: the embedded simulator hears what its host speaks). The deadlines allow for the frames'
        wire time at the new speed either way."""
        if line == self.settings.line:
            return
        if not isinstance(self._port, socket.socket):
            self._port.baudrate, self._port.parity, self._port.stopbits = line.baud, line.parity, line.stopbits
            self._port.reset_input_buffer()
            if self.settings.silence is None:
                self._exchange.settle = _frame_gap(line.baud)
        self._exchange.char_s, self._exchange.baud = _char_time(line), line.baud  # the deadlines' wire time
        self.settings = replace(self.settings, line=line)
        for listener in self.line_listeners:
            listener(line)

    @contextmanager
    def quick(self, timeout: float) -> Iterator[None]:
        """One try per request with a short timeout and no wait for late replies, for the block (probing ids that
        are silent by design, or a line speed on trial); the link's own settings afterwards."""
        ex = self._exchange
        saved = ex.timeout, ex.retries, ex.late_window, ex.flush_gap
        ex.timeout, ex.retries, ex.late_window, ex.flush_gap = timeout, 0, 0.0, min(ex.flush_gap, timeout / 2)
        try:
            yield
        finally:
            ex.timeout, ex.retries, ex.late_window, ex.flush_gap = saved

    def hurry(self) -> None:
        """For a bus scan, where most ids are silent by design: after a silent try, neither wait for a late reply
        nor for a long quiet gap (a late reply then shows up as a stray frame at the next id)."""
        self._exchange.late_window = 0.0
        self._exchange.flush_gap = 0.0

    def close(self) -> None:
        self._port.close()


def _char_time(line: LineSettings) -> float:
    """Seconds one character takes on the line: start bit, data bits, parity bit, stop bits."""
    return (1 + line.bytesize + (line.parity != "N") + line.stopbits) / line.baud


def _frame_gap(baud: int) -> float:
    """RTU's inter-frame silence (3.5 characters; a fixed 1.75 ms above 19200 baud)."""
    return 3.5 * 11 / baud if baud <= 19200 else 0.00175


class _SocketWire:
    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock

    def send(self, data: bytes) -> None:
        self.sock.setblocking(True)
        self.sock.sendall(data)

    def recv(self, timeout: float) -> bytes:
        if not select.select([self.sock], [], [], timeout)[0]:
            return b""
        if not (data := self.sock.recv(4096)):
            raise ConnectionError("closed by the other end")
        return data


class _SerialWire:
    def __init__(self, port: serial.SerialBase) -> None:  # pyserial, opened by link.ports.open_serial
        self.port = port

    def send(self, data: bytes) -> None:
        self.port.write(data)

    def recv(self, timeout: float) -> bytes:
        if hasattr(self.port, "fileno"):
            if not select.select([self.port], [], [], timeout)[0]:
                return b""
            return self.port.read(self.port.in_waiting or 1)
        if self.port.timeout != timeout:
            self.port.timeout = timeout
        data = self.port.read(1)
        return data + self.port.read(self.port.in_waiting) if data and self.port.in_waiting else data
