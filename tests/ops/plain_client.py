"""An independent reader for tests that judge stored values: pymodbus' own client against `sim serve`, without
servotool's link or recovery."""

from __future__ import annotations


def read_registers(port: str, address: int, count: int = 1, unit: int = 1) -> list[int]:
    """Holding registers read by pymodbus' own client (RTU framing over TCP), not by servotool."""
    from pymodbus import FramerType
    from pymodbus.client import ModbusTcpClient

    host, _, number = port.removeprefix("tcp://").rpartition(":")
    client = ModbusTcpClient(host, port=int(number), framer=FramerType.RTU, timeout=3)
    try:
        assert client.connect(), f"pymodbus cannot connect to {port}"
        reply = client.read_holding_registers(address, count=count, device_id=unit)
        assert not reply.isError(), reply
        return list(reply.registers)
    finally:
        client.close()
