"""Error types; each carries the process exit code the CLI uses for it."""

from __future__ import annotations

from typing import ClassVar


class ServoError(Exception):
    """Base class: a failure the user should read as one line."""

    exit_code = 1


class UsageError(ServoError):
    """Bad input: unknown code, value out of range, bad file or option."""

    exit_code = 2


class ProfileError(UsageError):
    """A profile is missing or broken."""


class DeviceError(ServoError):
    """The link or the drive failed: timeout, CRC error, Modbus exception."""

    exit_code = 1


class ModbusException(DeviceError):
    """The drive answered with a Modbus exception response."""

    NAMES: ClassVar[dict[int, str]] = {
        1: "illegal function",
        2: "illegal data address",
        3: "illegal data value",
        4: "slave device failure",
        5: "acknowledge",
        6: "slave device busy",
    }

    def __init__(self, code: int, what: str) -> None:
        self.code = code
        name = self.NAMES.get(code, "unknown exception")
        super().__init__(f"{what}: drive answered Modbus exception {code:02d} ({name})")


class VerifyError(ServoError):
    """A value read back differs from what was written, or an expectation failed."""

    exit_code = 3
