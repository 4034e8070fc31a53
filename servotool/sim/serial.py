"""The simulated drives as an RTU slave on a serial line, framed as Modbus over Serial Line 2.5.1.1 has it.

A frame ends at a silence of 3.5 characters (1.75 ms above 19200 baud): what came before it is one frame, answered
when its CRC holds and dropped when it does not, so an incomplete request never swallows the next one. A frame
whose length its head already tells (a read, a single write, a multiple write by its byte count) is answered as
soon as it is in with a valid CRC, as libmodbus does, so the line's speed is not spent waiting; a CRC-valid frame
that disagrees with its own byte count is one the silence ended, and gets exception 03.

pymodbus' RTU framer finds frames in a byte stream by their length alone, with no clock: after a truncated request,
or an FC16 whose byte count promises more than it carries, it waits for the missing bytes, takes the next request
as them, and drops both. Over TCP (sim/server.py) there is no silence to keep, and pymodbus serves.
"""

from __future__ import annotations

import os
import select
import threading
from collections.abc import Callable

from servotool.errors import DeviceError
from servotool.link.crc import crc_ok, with_crc
from servotool.link.ports import open_serial
from servotool.model.profile import LineSettings
from servotool.sim.line import WRITE_CODES, Line, refusal
from servotool.sim.virtual import READ_CODES

MAX_FRAME = 256  # the longest RTU frame
IDLE_S = 0.25  # how often an idle line checks whether it should stop


def silence_s(line: LineSettings) -> float:
    """The 3.5-character silence that ends a frame (a fixed 1.75 ms above 19200 baud)."""
    char = (1 + line.bytesize + (line.parity != "N") + line.stopbits) / line.baud
    return 3.5 * char if line.baud <= 19200 else 0.00175


def expected_length(frame: bytes) -> int | None:
    """The length a request frame's head promises (None until it tells, or for a function without a rule)."""
    if len(frame) < 2:
        return None
    fc = frame[1]
    if fc in (*READ_CODES, 1, 2, 4, 5, 6):  # every function of fixed request length, served or refused
        return 8
    if fc in (15, 16):
        return 9 + frame[6] if len(frame) >= 7 else None
    return None


class SerialSlave:
    """Answers RTU requests on a serial port for the drives on one line until `stop` is set."""

    def __init__(
        self,
        port: str,
        served: Line,
        line: LineSettings,
        trace: Callable[[bool, bytes], None] | None = None,
    ) -> None:
        self.line = served
        self.name, self.trace = port, trace
        self.silence = silence_s(line)
        # Linux refuses parity on a pty on some opens only (a second open meets it when the first did not): open
        # twice, so that a setting the port cannot do is named now rather than never.
        open_serial(port, line, IDLE_S, doing="serve on").close()
        self.port = open_serial(port, line, IDLE_S, doing="serve on")
        self._fd: int | None = self.port.fileno() if hasattr(self.port, "fileno") else None
        self.stop = threading.Event()

    def serve(self, ready: Callable[[], None] | None = None) -> None:
        """Read frames and answer them until stopped (or the port goes away)."""
        buf = b""
        if ready:
            ready()
        try:
            while not self.stop.is_set():
                try:
                    chunk = self._read(self.silence if buf else IDLE_S)
                except OSError as exc:  # the adapter was unplugged, the pty's other end closed
                    raise DeviceError(f"serving on {self.name}: the port went away ({exc})") from None
                if chunk:
                    buf = self._complete(buf + chunk)
                    if len(buf) > MAX_FRAME:
                        buf = b""  # no frame is this long: noise
                elif buf:  # the silence ended the frame: all of it is answered, or nothing
                    if len(buf) >= 4 and crc_ok(buf):
                        self._answer(buf)
                    buf = b""
        finally:
            self.port.close()

    def _read(self, timeout: float) -> bytes:
        """Bytes that came within `timeout` (b"" after that much silence)."""
        port = self.port
        if self._fd is not None:  # POSIX: one select and one read, not pyserial's loop (a pty answers in 0.1 ms)
            if not select.select([self._fd], [], [], timeout)[0]:
                return b""
            if not (data := os.read(self._fd, MAX_FRAME)):
                raise ConnectionError("end of file")  # readable yet empty: the other end is gone
            return data
        if port.timeout != timeout:
            port.timeout = timeout
        data = port.read(1)
        return data + port.read(port.in_waiting) if data and port.in_waiting else data

    def _complete(self, buf: bytes) -> bytes:
        """Answer the frame `buf` starts with when its head says it is all in and its CRC holds; what is left."""
        n = expected_length(buf)
        if n is not None and len(buf) >= n and crc_ok(buf[:n]):
            self._answer(buf[:n])
            return buf[n:]
        return buf

    def _answer(self, frame: bytes) -> None:
        if self.trace:
            self.trace(False, frame)
        if (reply := self._reply(frame)) is not None:
            if self.trace:
                self.trace(True, reply)
            if self._fd is not None:
                os.write(self._fd, reply)
            else:
                self.port.write(reply)

    def _reply(self, frame: bytes) -> bytes | None:
        """The reply frame to a CRC-valid request (None: silence, for a unit nobody serves or a broadcast)."""
        unit, pdu = frame[0], frame[1:-2]
        fc = pdu[0]
        drives = list(self.line.drives.values()) if unit == 0 else [d for d in [self.line.drives.get(unit)] if d]
        if not drives:
            return None
        if (code := refusal(pdu)) is not None:
            return None if unit == 0 else with_crc(bytes([unit, fc | 0x80, code]))
        address = int.from_bytes(pdu[1:3], "big")
        if fc == 6:
            values: list[int] | None = [int.from_bytes(pdu[3:5], "big")]
        elif fc in WRITE_CODES:
            values = [int.from_bytes(pdu[6 + 2 * i : 8 + 2 * i], "big") for i in range(pdu[5] // 2)]
        else:
            values = None
        count = len(values) if values is not None else int.from_bytes(pdu[3:5], "big")
        if unit == 0:  # a broadcast: every drive applies the write, none answers
            if values is not None:
                for drive in drives:
                    self.line.serve(drive, fc, address, count, values)
            return None
        result, delay = self.line.serve(drives[0], fc, address, count, values)
        if result is None:  # the drive listens at another speed (its baud entry): it hears only garbage
            return None
        if isinstance(result, int):
            return with_crc(bytes([unit, fc | 0x80, result]))
        if delay:
            self.stop.wait(delay)
        if values is None:
            data = b"".join(v.to_bytes(2, "big") for v in result)
            return with_crc(bytes([unit, fc, len(data)]) + data)
        return frame if fc == 6 else with_crc(frame[:6])
