"""The one adapter over pymodbus' client side: open a port, read/write registers, build/parse RTU frames.

Everything else in servotool talks to `Link`, never to pymodbus directly, because pymodbus' API churns."""

from __future__ import annotations

import logging
import re
from collections.abc import Callable

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException
from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse
from pymodbus.pdu.register_message import (
    ReadHoldingRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteSingleRegisterRequest,
)

from servotool.errors import DeviceError
from servotool.errors import ModbusException as DriveException
from servotool.link.ports import LinkSettings, Trace, parse_tcp

# pymodbus logs every dropped frame at error level; our own errors say what happened.
logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class ModbusLink:
    """A pymodbus sync client speaking RTU frames over a serial line or a TCP socket."""

    def __init__(self, settings: LinkSettings, trace: Trace | None = None) -> None:
        self.settings = settings
        self.trace = trace
        self.requests = 0
        self._received = b""   # bytes that came back during the current request, valid frame or not
        hook = self._trace_packet
        tcp = parse_tcp(settings.port)
        self._client: ModbusTcpClient | ModbusSerialClient
        if tcp:
            self._client = ModbusTcpClient(
                tcp[0], port=tcp[1], framer=FramerType.RTU, timeout=settings.timeout, retries=settings.retries,
                trace_packet=hook, reconnect_delay=0,
            )
        else:
            self._client = ModbusSerialClient(
                settings.port, framer=FramerType.RTU, baudrate=settings.line.baud, parity=settings.line.parity,
                stopbits=settings.line.stopbits, bytesize=settings.line.bytesize, timeout=settings.timeout,
                retries=settings.retries, trace_packet=hook, reconnect_delay=0,
            )
        if not self._client.connect():
            self._client.close()
            raise DeviceError(f"cannot open port {settings.port}: {self._why_not_open()}")

    def _why_not_open(self) -> str:
        if parse_tcp(self.settings.port):
            return "connection refused or host unreachable"
        return "no such device, busy, or permission denied"

    def _drain(self) -> None:
        """Drop bytes nobody asked for: RTU has no transaction id, so a reply that came after its timeout (and a
        retry) would otherwise be taken for the answer to the next request."""
        sock = getattr(self._client, "socket", None)
        if sock is None:
            return
        try:
            if hasattr(sock, "reset_input_buffer"):      # pyserial
                sock.reset_input_buffer()
                return
            timeout = sock.gettimeout()
            sock.setblocking(False)
            try:
                while sock.recv(4096):
                    pass
            except (BlockingIOError, InterruptedError):
                pass
            finally:
                sock.settimeout(timeout)
        except OSError:
            pass    # a broken link shows up on the request itself

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if not sending:
            self._received += data
        if self.trace:
            self.trace(sending, data)
        return data

    def _call(self, what: str, fn: Callable[[], object]) -> object:
        self.requests += 1
        self._drain()
        self._received = b""
        try:
            response = fn()
        except ConnectionException as exc:
            raise DeviceError(f"{what}: link lost ({_short(exc)})") from None
        except ModbusIOException:
            tries = f"{self.settings.retries + 1} tr{'y' if self.settings.retries == 0 else 'ies'}"
            if self._received:
                raise DeviceError(
                    f"{what}: garbled response after {tries}, {len(self._received)} bytes with a bad CRC or "
                    f"framing (noise, termination, baud/parity mismatch, or two masters on the line)") from None
            raise DeviceError(
                f"{what}: no response within {self.settings.timeout:g} s after {tries} "
                f"(wrong unit id, baud/parity, wiring, or the drive is off)") from None
        except ModbusException as exc:
            raise DeviceError(f"{what}: {_short(exc)}") from None
        if isinstance(response, ExceptionResponse):
            raise DriveException(response.exception_code, what)
        if getattr(response, "isError", lambda: False)():
            raise DeviceError(f"{what}: invalid response")
        return response

    def read(self, unit: int, address: int, count: int) -> list[int]:
        what = f"read {count} register(s) at {address} (0x{address:04X}) from unit {unit}"
        response = self._call(what, lambda: self._client.read_holding_registers(address, count=count, device_id=unit))
        regs = list(getattr(response, "registers", []))
        if len(regs) != count:
            raise DeviceError(f"{what}: drive returned {len(regs)} registers")
        return regs

    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True) -> None:
        what = f"write {len(values)} register(s) at {address} (0x{address:04X}) to unit {unit}"
        if len(values) == 1 and not multiple:
            self._call(what, lambda: self._client.write_register(address, values[0], device_id=unit))
        else:
            self._call(what, lambda: self._client.write_registers(address, values, device_id=unit))

    def close(self) -> None:
        self._client.close()


def _short(exc: Exception) -> str:
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return re.sub(r"^Modbus Error: \[[^\]]*\]\s*", "", text)


_FRAMER = FramerRTU(DecodePDU(is_server=False))


def read_request_frame(unit: int, address: int, count: int) -> bytes:
    """The RTU frame (with CRC) of an FC03 request, as this tool sends it."""
    return _FRAMER.buildFrame(ReadHoldingRegistersRequest(address=address, count=count, dev_id=unit))


def write_request_frame(unit: int, address: int, values: list[int], *, multiple: bool = True) -> bytes:
    """The RTU frame of an FC06 (single, multiple=False) or FC16 write request."""
    if len(values) == 1 and not multiple:
        return _FRAMER.buildFrame(WriteSingleRegisterRequest(address=address, registers=values, dev_id=unit))
    return _FRAMER.buildFrame(WriteMultipleRegistersRequest(address=address, registers=values, dev_id=unit))


def parse_response_frame(frame: bytes) -> tuple[int, int, list[int]]:
    """(unit, function code, registers) of a response frame; DeviceError on a bad CRC or an exception reply."""
    _used, pdu = FramerRTU(DecodePDU(is_server=False)).handleFrame(frame, 0, 0)
    if pdu is None:
        raise DeviceError(f"not a valid RTU response frame (CRC or length): {frame.hex(' ')}")
    if isinstance(pdu, ExceptionResponse):
        raise DriveException(pdu.exception_code, f"unit {pdu.dev_id}")
    return pdu.dev_id, pdu.function_code, list(getattr(pdu, "registers", []))
