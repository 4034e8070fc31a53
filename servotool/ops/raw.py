"""Registers by address, for what a profile does not map: read a block (as 16- or 32-bit values, once or polled),
write registers and read them back."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from dataclasses import dataclass

from servotool.clock import Clock, RealClock
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


# A value type: (registers it takes, struct format of its big-endian bytes).
VALUE_TYPES: dict[str, tuple[int, str]] = {
    "int16": (1, ">h"),
    "uint16": (1, ">H"),
    "int32": (2, ">i"),
    "uint32": (2, ">I"),
    "float32": (2, ">f"),
}
WORD_ORDERS = ("big", "little")
READ_FUNCTIONS = (1, 2, 3, 4)  # coils, discrete inputs, holding and input registers
BIT_FUNCTIONS = (1, 2)
MAX_BITS = 2000  # the specification's limit for an FC01/FC02 read


@dataclass(frozen=True)
class Value:
    """One value read: its first register's address, the registers it came from, and what they hold as its type."""

    address: int
    words: tuple[int, ...]
    value: int | float


def width(kind: str) -> int:
    """Registers one value of this type takes; UsageError for a type not in VALUE_TYPES."""
    if kind not in VALUE_TYPES:
        raise UsageError(f"--type must be one of {', '.join(VALUE_TYPES)}, not '{kind}'")
    return VALUE_TYPES[kind][0]


def decode(address: int, words: list[int], kind: str, word_order: str = "big") -> list[Value]:
    """Registers as values of `kind`; a 32-bit value's high word first (`big`, as mbpoll and most drives) or its low
    word first (`little`). Bytes within a register are always big-endian, as Modbus sends them."""
    if word_order not in WORD_ORDERS:
        raise UsageError(f"--word-order must be big or little, not '{word_order}'")
    n, fmt = width(kind), VALUE_TYPES[kind][1]
    values = []
    for i in range(0, len(words) - n + 1, n):
        group = tuple(words[i : i + n])
        ordered = group if word_order == "big" else group[::-1]
        (value,) = struct.unpack(fmt, b"".join(w.to_bytes(2, "big") for w in ordered))
        values.append(Value(address + i, group, value))
    return values


def read_values(
    drive: Drive, address: int, count: int, kind: str = "uint16", word_order: str = "big", fc: int = 3
) -> list[Value]:
    """`count` values of `kind` from `address` on, in one FC03 (holding) or FC04 (input registers) read; FC01
    (coils) and FC02 (discrete inputs) read `count` bits, each a value 0 or 1."""
    if fc in BIT_FUNCTIONS:
        if kind != "uint16" or word_order != "big":
            raise UsageError(f"--fc {fc} reads bits: --type and --word-order are for registers")
        return [Value(address + i, (b,), b) for i, b in enumerate(read_registers(drive, address, count, fc))]
    return decode(address, read_registers(drive, address, count * width(kind), fc), kind, word_order)


def poll(
    drive: Drive,
    address: int,
    count: int,
    kind: str = "uint16",
    word_order: str = "big",
    *,
    interval: float,
    polls: int | None = None,
    clock: Clock | None = None,
    fc: int = 3,
) -> Iterator[tuple[float, list[Value]]]:
    """(seconds since the first poll, its values) every `interval` s, `polls` times (None: until the caller stops);
    a poll that overruns its slot starts the next one at once rather than bunching up."""
    check_poll(interval, polls)
    decode(address, [], kind, word_order)  # a bad type or word order is refused before the first read
    return _polls(drive, address, count, kind, word_order, interval, polls, clock or RealClock(), fc)


def check_poll(interval: float, polls: int | None) -> None:
    """UsageError for a poll interval or count that cannot be run (before a port opens)."""
    if interval <= 0:
        raise UsageError(f"--interval must be above 0 s, not {interval:g}")
    if polls is not None and polls < 1:
        raise UsageError(f"--count must be at least 1, not {polls}")


def _polls(
    drive: Drive,
    address: int,
    count: int,
    kind: str,
    word_order: str,
    interval: float,
    polls: int | None,
    clock: Clock,
    fc: int,
) -> Iterator[tuple[float, list[Value]]]:
    start = clock.now()
    done = 0
    while polls is None or done < polls:
        if done:
            clock.sleep(start + done * interval - clock.now())
        yield clock.now() - start, read_values(drive, address, count, kind, word_order, fc)
        done += 1


def read_registers(drive: Drive, address: int, count: int, fc: int = 3) -> list[int]:
    """`count` registers from `address` on: FC03 holding, FC04 input registers (FC01/FC02: bits 0/1).
    ModbusException (01) from a drive that lacks the function."""
    if fc not in READ_FUNCTIONS:
        raise UsageError(f"--fc {fc}: reads are FC01 (coils), FC02 (discrete inputs), FC03 (holding), FC04 (input)")
    limit = MAX_BITS if fc in BIT_FUNCTIONS else drive.profile.limits.max_read
    if not 1 <= count <= limit:
        raise UsageError(
            f"count {count}: the drive reads 1..{limit} {'bits' if limit == MAX_BITS else 'registers'} at a time"
        )
    if address + count > 0x10000:
        raise UsageError(f"registers {address}..{address + count - 1} go past 65535")
    return drive.link.read(drive.unit, address, count, fc=fc)


def write_registers(drive: Drive, address: int, values: list[int]) -> list[int]:
    """Write registers from `address` on (FC06 for one, FC16 for several) and read them back; the values read.
    VerifyError when they differ; UsageError when the profile says the drive takes no FC16 or reads fewer."""
    if len(values) == 1:
        return [write_register(drive, address, values[0])]
    limits = drive.profile.limits
    if not limits.write_multiple:
        raise UsageError(f"{drive.profile.model} takes no FC16 (write several registers): write them one at a time")
    if len(values) > limits.max_read:
        raise UsageError(f"{len(values)} registers: the drive reads back 1..{limits.max_read} at a time")
    if address + len(values) > 0x10000:
        raise UsageError(f"registers {address}..{address + len(values) - 1} go past 65535")
    drive.link.write(drive.unit, address, values, multiple=True)
    back = drive.link.read(drive.unit, address, len(values))
    if back != values:
        raise VerifyError(f"registers {address}.. (0x{address:04X}): wrote {values}, read back {back}")
    return back


def write_coils(drive: Drive, address: int, bits: list[int], *, many: bool = False) -> list[int]:
    """Write coils from `address` on (FC05 for one, FC15 for several or with `many`) and read them back (FC01);
    the bits read. VerifyError when they differ; ModbusException (01) from a drive that has no coils."""
    if any(b not in (0, 1) for b in bits):
        raise UsageError(f"a coil is 0 or 1, not {next(b for b in bits if b not in (0, 1))}")
    if address + len(bits) > 0x10000 or len(bits) > MAX_BITS:
        raise UsageError(f"{len(bits)} coils from {address}: at most {MAX_BITS}, up to address 65535")
    drive.link.write(drive.unit, address, bits, multiple=many or len(bits) > 1, coils=True)
    back = drive.link.read(drive.unit, address, len(bits), fc=1)
    if back != bits:
        raise VerifyError(f"coils {address}.. (0x{address:04X}): wrote {bits}, read back {back}")
    return back


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
