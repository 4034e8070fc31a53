"""Registers by address, for what a profile does not map: read a block, write one register and read it back."""

from __future__ import annotations

from servotool.drive import Drive
from servotool.errors import UsageError, VerifyError
from servotool.model.profile import Entry


def parse_address(text: str) -> int:
    """A register address: decimal or 0x hexadecimal, 0..65535."""
    try:
        address = int(text.strip(), 0)
    except ValueError:
        raise UsageError(f"'{text}' is not a register address (decimal, or hex as 0x2004)") from None
    if not 0 <= address <= 0xFFFF:
        raise UsageError(f"register address {address} is outside 0..65535")
    return address


def parse_word(text: str) -> int:
    """A register value: -32768..65535 (decimal or 0x hex); negatives as two's complement."""
    try:
        value = int(text.strip(), 0)
    except ValueError:
        raise UsageError(f"'{text}' is not a register value (an integer, or hex as 0x00FF)") from None
    if not -0x8000 <= value <= 0xFFFF:
        raise UsageError(f"register value {value} does not fit 16 bits (-32768..65535)")
    return value & 0xFFFF


def owner(drive: Drive, address: int) -> Entry | None:
    """The profile entry whose registers include this address, if any."""
    return next((e for e in drive.profile.entries if address in e.addresses), None)


def read_registers(drive: Drive, address: int, count: int) -> list[int]:
    limit = drive.profile.limits.max_read
    if not 1 <= count <= limit:
        raise UsageError(f"count {count}: the drive reads 1..{limit} registers at a time")
    if address + count > 0x10000:
        raise UsageError(f"registers {address}..{address + count - 1} go past 65535")
    return drive.link.read(drive.unit, address, count)


def write_register(drive: Drive, address: int, value: int) -> int:
    """Write one register (FC06) and read it back; the value read. VerifyError when it differs."""
    target = Entry(
        code=f"register {address}",
        cls="Pn",
        name=f"register {address} (0x{address:04X})",
        address=address,
        type="u16",
        min=0,
        max=0xFFFF,
    )
    drive.write_raw(target, value)
    back = drive.link.read(drive.unit, address, 1)[0]
    if back != value:
        raise VerifyError(f"register {address} (0x{address:04X}): wrote {value}, read back {back}")
    return back
