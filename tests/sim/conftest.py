"""Register access to a simulated drive by entry code, through its public read/write as a Modbus master has it."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from servotool.model.codec import raw_to_words, words_to_raw
from servotool.sim.device import SimulatedDrive


@dataclass
class Registers:
    drive: SimulatedDrive

    def write(self, code: str, raw: int) -> None:
        entry = self.drive.profile.entry(code)
        self.drive.write(entry.address, raw_to_words(entry, raw))

    def read(self, code: str) -> int:
        """An entry's raw value (signed where the entry is), read through the drive (the plant runs up to now)."""
        entry = self.drive.profile.entry(code)
        return words_to_raw(entry, self.drive.read(entry.address, entry.words))

    def history(self, depth: int = 3) -> list[int]:
        """The alarm history monitors, latest first."""
        return [self.read(self.drive.profile.roles[f"alarm_history_{n}"]) for n in range(1, depth + 1)]


@pytest.fixture
def regs() -> type[Registers]:
    return Registers
