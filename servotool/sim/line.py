"""The simulated drives on one line as a Modbus slave serves them: a decoded request in, registers or an exception out.

One home for what the slave does with a request: pymodbus' server (sim/server.py: `sim serve`, and the embedded
simulator behind `--port sim`) hands it each request it decoded. As on a real RS485 bus a unit nobody serves stays
silent, and so does every drive for a broadcast (unit 0) they all apply.
"""

from __future__ import annotations

import logging
import threading

from servotool.sim.device import SimulatedDrive
from servotool.sim.registers import DEVICE_FAILURE, ILLEGAL_FUNCTION, ILLEGAL_VALUE, SimRefusal
from servotool.sim.virtual import READ_CODES, wire_time

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


class Line:
    """The drives on one line, by unit; `lock` serialises requests (a server's thread and others touching the
    drives)."""

    def __init__(self, drives: list[SimulatedDrive], lock: threading.Lock | None = None) -> None:
        self.drives = {d.unit: d for d in drives}
        self.lock = lock or threading.Lock()

    def serve(
        self, drive: SimulatedDrive, fc: int, address: int, count: int, values: list[int] | None
    ) -> tuple[list[int] | int, float]:
        """Registers read (none for a write) or the exception code, and the seconds the drive's emulated line
        takes to answer (its `line_baud`; 0 without)."""
        try:
            with self.lock:
                drive.bank.entries_in(address, count)  # an unmapped address is exception 02 before all else
                if values is not None:
                    drive.write(address, values)
                    registers: list[int] = []
                else:
                    registers = drive.read(address, count)
        except SimRefusal as exc:
            return exc.code, 0.0
        except Exception:  # a simulator bug must answer like a faulty slave, not kill the server
            logging.getLogger("servotool.sim").exception("simulator failure")
            return DEVICE_FAILURE, 0.0
        return registers, wire_time(fc, count, drive.line_baud) if drive.line_baud else 0.0
