"""The simulated drives on one line as a Modbus slave serves them: a decoded request in, registers or an exception out.

One home for what the slave does with a request: pymodbus' server (sim/server.py: `sim serve`, and the embedded
simulator behind `--port sim`) hands it each request it decoded. As on a real RS485 bus a unit nobody serves stays
silent, and so does every drive for a broadcast (unit 0) they all apply.
"""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass

from servotool.errors import UsageError
from servotool.model.profile import LineSettings
from servotool.sim.device import LINE_FACTORY, LINE_FAST, SimulatedDrive, line_choice
from servotool.sim.registers import DEVICE_FAILURE, ILLEGAL_FUNCTION, ILLEGAL_VALUE, SimRefusal
from servotool.sim.virtual import READ_CODES, wire_time

LINE_ENV = "SERVOTOOL_SIM_LINE_BAUD"

WRITE_CODES = (6, 16)
MAX_READ, MAX_WRITE = 125, 123  # the specification's quantity limits (FC03/04 and FC16)


def refusal(pdu: bytes) -> int | None:
    """The exception a slave answers before touching any register, as the Modbus specification has it: 01 for a
    function the drive lacks (at any address), 03 for a quantity out of range (0, over 125 read, over 123
    written) or a length that disagrees with the request (a byte count that is not twice the quantity or not the
    data that came); None for a request to serve."""
    fc = pdu[0] if pdu else 0
    if fc not in READ_CODES + WRITE_CODES:
        return ILLEGAL_FUNCTION
    if len(pdu) < 5 or (fc in (*READ_CODES, 6) and len(pdu) != 5):
        return ILLEGAL_VALUE  # a frame the silence ended short (or long) of what its function needs
    if fc != 6:
        count = int.from_bytes(pdu[3:5], "big")
        limit = MAX_READ if fc in READ_CODES else MAX_WRITE
        if not 1 <= count <= limit or (fc == 16 and (len(pdu) < 6 or pdu[5] != 2 * count or len(pdu) != 6 + pdu[5])):
            return ILLEGAL_VALUE
    return None


@dataclass(frozen=True)
class Emulated:
    """The RS485 line a simulated drive's answers are timed by: each one comes after its request's and its own
    wire time, as on a real line at this speed and character format."""

    line: LineSettings

    @property
    def bits(self) -> int:
        """Bits a character: start, data, parity, stop."""
        return 1 + self.line.bytesize + (self.line.parity != "N") + self.line.stopbits

    def seconds(self, fc: int, count: int) -> float:
        return wire_time(fc, count, self.line.baud, self.bits)

    def describe(self) -> str:
        """'9600 baud 8N1'."""
        return f"{self.line.baud} baud {self.line.bytesize}{self.line.parity}{self.line.stopbits}"


def env_choice() -> str | int | None:
    """The line SERVOTOOL_SIM_LINE_BAUD asks of every simulated drive (fast, factory or a baud rate), None when
    unset; UsageError naming the variable for anything else."""
    if not (text := os.environ.get(LINE_ENV, "").strip()):
        return None
    try:
        return line_choice(text)
    except ValueError as exc:
        raise UsageError(f"{LINE_ENV}: {exc}") from None


def emulated(
    drive: SimulatedDrive,
    line: LineSettings | None,
    choice: str | int | None = None,
    *,
    wired: bool = False,
    default: str | int | None = None,
) -> Emulated | None:
    """The line a drive's answers are timed by, None for none. `choice` (sim serve --line-baud) wins; then the
    drive's own `sim config --line-baud`; where that is left at factory, `default` (SERVOTOOL_SIM_LINE_BAUD).
    "factory" is `line` (the connection's settings), else the profile's factory settings, and nothing to add on
    a serial port (`wired`), whose own line carries the bytes; a baud rate keeps that line's character format;
    "fast" is none."""
    chosen = choice if choice is not None else drive.line_baud
    if chosen == LINE_FACTORY and choice is None and default is not None:
        chosen = default
    if chosen == LINE_FAST or (chosen == LINE_FACTORY and wired):
        return None
    base = line or drive.profile.line
    if (own := entry_baud(drive)) is not None:
        return Emulated(LineSettings(own, base.parity, base.stopbits, base.bytesize))
    if chosen == LINE_FACTORY:
        return Emulated(base)
    return Emulated(LineSettings(int(chosen), base.parity, base.stopbits, base.bytesize))


def entry_baud(drive: SimulatedDrive) -> int | None:
    """The speed the drive's own baud entry sets, where the profile maps its codes (serial.boost) and the entry
    holds another code than the factory line's; None while it holds the factory code (the line is then the one
    the drives are reached at, or the emulation asked for) or where its codes are not known. A change takes
    effect as the manual has it, at once (the value in effect)."""
    boost = drive.profile.boost
    if not boost.available:
        return None
    code = drive.bank.effective_value(boost.code)
    if code == boost.code_of(drive.profile.line.baud):
        return None
    return boost.rates.get(code)


class Line:
    """The drives on one line, by unit; `lock` serialises requests (a server's thread and others touching the
    drives). Each answer waits for its wire time on the emulated line (see `emulated`: `line` is the line the
    drives are reached at, `choice` what overrides their own setting), none with the choice "fast"."""

    def __init__(
        self,
        drives: list[SimulatedDrive],
        lock: threading.Lock | None = None,
        line: LineSettings | None = None,
        choice: str | int | None = None,
        *,
        wired: bool = False,
        default: str | int | None = None,
    ) -> None:
        self.drives = {d.unit: d for d in drives}
        self.lock = lock or threading.Lock()
        self.line, self.choice, self.wired, self.default = line, choice, wired, default
        self.host: LineSettings | None = None  # what the master speaks, where it is known (the embedded simulator)

    def emulated(self, drive: SimulatedDrive) -> Emulated | None:
        return emulated(drive, self.line, self.choice, wired=self.wired, default=self.default)

    def describe(self) -> str:
        """What the drives' answers are timed by, for a banner: 'line emulated at 9600 baud 8N1', 'line NOT
        emulated: fast', per unit where they differ."""
        said = {u: _timing_text(self.emulated(d), self.wired) for u, d in self.drives.items()}
        if len(set(said.values())) == 1:
            return next(iter(said.values()))
        return "; ".join(f"unit {u}: {text}" for u, text in said.items())

    def serve(
        self, drive: SimulatedDrive, fc: int, address: int, count: int, values: list[int] | None
    ) -> tuple[list[int] | int | None, float]:
        """Registers read (none for a write) or the exception code, and the seconds the emulated line takes to
        carry the request and the answer (0 when fast); None for no answer at all: a drive whose baud entry set
        another speed than the master speaks (self.host) hears only garbage. A write that changes the drive's
        speed is answered at the old one, then the new one holds."""
        try:
            with self.lock:
                # the speed in effect before this request (as the last request left the drive's state)
                timed = self.emulated(drive)
                deaf = self.host is not None and (own := entry_baud(drive)) is not None and own != self.host.baud
                if deaf:
                    return None, 0.0
                drive.bank.entries_in(address, count)  # an unmapped address is exception 02 before all else
                if values is not None:
                    drive.write(address, values)
                    registers: list[int] = []
                else:
                    registers = drive.read(address, count)
        except SimRefusal as exc:
            return exc.code, _seconds(timed, 3, 0)  # a request and a 5-character exception reply
        except Exception:  # a simulator bug must answer like a faulty slave, not kill the server
            logging.getLogger("servotool.sim").exception("simulator failure")
            return DEVICE_FAILURE, 0.0
        return registers, _seconds(timed, fc, count)


def _seconds(timed: Emulated | None, fc: int, count: int) -> float:
    return timed.seconds(fc, count) if timed is not None else 0.0


def _timing_text(timed: Emulated | None, wired: bool) -> str:
    if timed is not None:
        return f"line emulated at {timed.describe()}"
    return "line timing: the serial port's own" if wired else "line NOT emulated: fast"
