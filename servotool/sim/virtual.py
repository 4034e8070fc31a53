"""An in-process link into simulated drives on virtual time, for tests and benchmarks.

It answers like the served simulator (a refused request is a Modbus exception) without sockets or threads, and
every request costs the virtual clock its wire time at the given baud rate, so a host-side algorithm sees the same
sampling rate it would see on that line.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from servotool.clock import VirtualClock
from servotool.errors import DeviceError, ModbusException
from servotool.model.setup import requirements
from servotool.sim.device import SimulatedDrive
from servotool.sim.registers import SimRefusal

READ_CODES = (3,)  # no manual lists FC04 (SD25 ch.1.2, SDC: 03/06/16 only; IS620P prints no Modbus chapter)
TURNAROUND_S = 0.0005  # the drive's reply delay and the host's turnaround, per request


def wire_time(fc: int, count: int, baud: int, bits: int = 11) -> float:
    """Seconds a request and its response occupy an RS485 line (`bits` a character: 11 for 8E1, 8O1 or 8N2, 10
    for 8N1; 3.5-character gaps)."""
    if fc in READ_CODES:
        chars = 8 + 5 + 2 * count
    elif fc == 16:
        chars = 9 + 2 * count + 8
    else:
        chars = 16
    return (chars + 7) * bits / baud


def make_motion_setup(sim: SimulatedDrive) -> None:
    """The profile's motion setup made on a simulated drive, stored and power-cycled (SD25's DI functions act only
    after a power cycle), then made again for anything a power-up clears: as a user sets up the drive."""
    for power_up in range(2):
        for req in requirements(sim.profile):
            now = sim.bank.effective_value(req.entry.code)
            sim.bank.apply_parameter(req.entry, (now & ~req.mask) | (req.wanted & req.mask))
        sim.bank.save_eeprom()
        if power_up == 0:
            sim.power_cycle()
    sim.firmware.plant.set_gains(sim.firmware._gains())


@dataclass(frozen=True)
class HostStalls:
    """A host that stalls now and then before it sends a request (a loaded laptop, a scheduler tick, a USB
    adapter's latency timer): each request, with probability `rate`, waits a uniform min_s..max_s first; seeded.
    With `after_reply`, that share of the stalls comes instead after the drive answered and before the host takes
    the answer (a client descheduled while its reply waits in the socket): the host then stamps the reading late."""

    rate: float
    max_s: float = 0.05
    seed: int = 1
    min_s: float = 0.01
    after_reply: float = 0.0


class VirtualLink:
    """A Link (servotool.link.ports.Link) straight into simulated drives, by unit id."""

    def __init__(
        self, drives: list[SimulatedDrive], clock: VirtualClock, baud: int = 115200, stalls: HostStalls | None = None
    ) -> None:
        self.drives = {d.unit: d for d in drives}
        self.clock, self.baud = clock, baud
        self.requests = 0
        self.stalls = stalls
        self._stall_rng = random.Random(stalls.seed if stalls else 0)

    def _stall(self) -> float:
        """Advance the clock by a stall before the request; returns a stall due after the reply instead (0: none)."""
        st, rng = self.stalls, self._stall_rng
        if st is None or rng.random() >= st.rate:
            return 0.0
        took = rng.uniform(st.min_s, st.max_s)
        if st.after_reply > 0 and rng.random() < st.after_reply:
            return took
        self.clock.advance(took)
        return 0.0

    def _drive(self, unit: int, what: str) -> SimulatedDrive:
        drive = self.drives.get(unit)
        if drive is None:
            raise DeviceError(f"{what}: no response (no simulated drive has unit {unit})")
        return drive

    def read(
        self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0), fc: int = 3, live: bool = False
    ) -> list[int]:
        """`count` registers; `spare` and `live` are not used: in process, a reply cannot be taken for another's. A
        function other than FC03, or one the drive's profile does not answer, is refused with exception 01, as the
        line's drive does (sim.line.refusal)."""
        what = f"read {count} register(s) at {address} from unit {unit}"
        if fc not in READ_CODES or fc not in self._drive(unit, what).profile.modbus_functions.answered:
            raise ModbusException(1, what)
        self.requests += 1
        late = self._stall()
        self.clock.advance(wire_time(3, count, self.baud) + TURNAROUND_S)
        try:
            return self._drive(unit, what).read(address, count)
        except SimRefusal as exc:
            raise ModbusException(exc.code, what) from None
        finally:
            self.clock.advance(late)

    def write(
        self,
        unit: int,
        address: int,
        values: list[int],
        *,
        multiple: bool = True,
        idempotent: bool = True,
        coils: bool = False,
    ) -> None:
        what = f"write {len(values)} register(s) at {address} to unit {unit}"
        fc = 16 if multiple or len(values) > 1 else 6
        if coils or fc not in self._drive(unit, what).profile.modbus_functions.answered:  # (sim.line.refusal)
            raise ModbusException(1, what)
        self.requests += 1
        late = self._stall()
        self.clock.advance(wire_time(fc, len(values), self.baud) + TURNAROUND_S)
        try:
            self._drive(unit, what).write(address, values)
        except SimRefusal as exc:
            raise ModbusException(exc.code, what) from None
        finally:
            self.clock.advance(late)

    def close(self) -> None:
        pass
