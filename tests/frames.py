"""RTU frames for tests: requests as servotool's master sends them, and replies decoded by an independent decoder
(pymodbus' framer), so a test compares servotool's bytes with the manuals' and with another implementation's."""

from __future__ import annotations

import logging

from pymodbus.framer import FramerRTU
from pymodbus.pdu import DecodePDU, ExceptionResponse

from servotool.errors import DeviceError, ModbusException
from servotool.link.rtu import READ, WRITE_MANY, WRITE_ONE, Request


def read_request_frame(unit: int, address: int, count: int) -> bytes:
    """The RTU frame (with CRC) of an FC03 request, as servotool sends it."""
    return Request(unit, READ, address, count).frame


def write_request_frame(unit: int, address: int, values: list[int], *, multiple: bool = True) -> bytes:
    """The RTU frame of an FC06 (single, multiple=False) or FC16 write request."""
    fc = WRITE_ONE if len(values) == 1 and not multiple else WRITE_MANY
    return Request(unit, fc, address, len(values), tuple(values)).frame


def parse_response_frame(frame: bytes) -> tuple[int, int, list[int]]:
    """(unit, function code, registers) of a response frame; DeviceError on a bad CRC, ModbusException on an
    exception reply."""
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)  # it logs a dropped frame as an error
    _used, pdu = FramerRTU(DecodePDU(is_server=False)).handleFrame(frame, 0, 0)
    if pdu is None:
        raise DeviceError(f"not a valid RTU response frame (CRC or length): {frame.hex(' ')}")
    if isinstance(pdu, ExceptionResponse):
        raise ModbusException(pdu.exception_code, f"unit {pdu.dev_id}")
    return pdu.dev_id, pdu.function_code, list(getattr(pdu, "registers", []))


def plain_read(port: str, address: int, count: int, unit: int = 1) -> list[int]:
    """Holding registers read by pymodbus' own client over RTU on TCP (a served simulator's tcp://HOST:N port):
    an independent reader, without servotool's link or its recovery."""
    from pymodbus import FramerType
    from pymodbus.client import ModbusTcpClient

    host, _, number = port.removeprefix("tcp://").rpartition(":")
    client = ModbusTcpClient(host, port=int(number), framer=FramerType.RTU, timeout=2)
    try:
        assert client.connect()
        reply = client.read_holding_registers(address, count=count, device_id=unit)
        assert not reply.isError(), reply
        return list(reply.registers)
    finally:
        client.close()
