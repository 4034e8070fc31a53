"""An independent reader for tests that judge motion or stored values: a plain pymodbus client over RTU-over-TCP
(`servotool sim serve`), not servotool's own drive code, so that no journal recovery, identity check or retry of
servotool's tidies up before the test looks."""

from __future__ import annotations

import logging

from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient

from servotool.model.codec import raw_to_eng, words_to_raw
from servotool.model.loader import load_profile
from servotool.model.profile import Entry, Profile


class Reader:
    """Reads (and, for a test's setup, writes) a served drive's registers by address, decoded with the profile's
    map only."""

    def __init__(self, port: str, profile: str, unit: int = 1) -> None:
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
        host, _, number = port.removeprefix("tcp://").rpartition(":")
        self.profile: Profile = load_profile(profile)
        self.unit = unit
        self.client = ModbusTcpClient(host, port=int(number), framer=FramerType.RTU, timeout=3, retries=2)
        assert self.client.connect(), f"cannot connect to {port}"

    def close(self) -> None:
        self.client.close()

    def __enter__(self) -> Reader:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def entry(self, code_or_role: str) -> Entry:
        return self.profile.entry(code_or_role)

    def raw(self, code_or_role: str) -> int:
        e = self.entry(code_or_role)
        reply = self.client.read_holding_registers(e.address, count=e.words, device_id=self.unit)
        assert not reply.isError(), f"{e.code}: {reply}"
        return words_to_raw(e, list(reply.registers))

    def eng(self, code_or_role: str) -> float:
        e = self.entry(code_or_role)
        return float(raw_to_eng(e, self.raw(code_or_role)))

    def write(self, code_or_role: str, raw: int) -> None:
        e = self.entry(code_or_role)
        assert e.words == 1
        reply = self.client.write_register(e.address, raw & 0xFFFF, device_id=self.unit)
        assert not reply.isError(), f"{e.code}: {reply}"
