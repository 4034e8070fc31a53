"""Opening drives for a resolved connection, with the embedded simulator for --port sim."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

from servotool.clock import Clock, RealClock
from servotool.config import Resolved
from servotool.drive import Drive
from servotool.link.modbus import ModbusLink
from servotool.link.ports import Trace, latency_advice
from servotool.link.rtu import crc_ok, with_crc

if TYPE_CHECKING:
    from servotool.sim.line import Line

_ADVISED: set[str] = set()


def sim_notice(resolved: Resolved, units: list[int]) -> str:
    ids = ",".join(str(u) for u in units)
    return (f"servotool: SIMULATED drive ({resolved.profile.model} profile '{resolved.profile.id}', unit {ids}); "
            f"no real hardware is involved")


class SimWire:
    """The embedded simulator's end of the line, in this process: each request frame goes to the simulator's
    slave (sim.line, as `sim serve` answers it) and its reply frame is there once its drive's emulated line would
    have carried it. A garbled request or a silent unit gets nothing: the exchange waits out its timeout, as on a
    real line. Frames, retries and the -v trace are the exchange's own, as with a port."""

    def __init__(self, line: Line, clock: Clock | None = None) -> None:
        self.line = line
        self.clock = clock or RealClock()
        self._reply = b""
        self._ready = 0.0

    def send(self, data: bytes) -> None:
        if len(data) < 4 or not crc_ok(data):
            return
        reply, delay = self.line.answer(data[0], data[1:-2])
        if reply is not None:
            self._reply += with_crc(data[:1] + reply)
            self._ready = self.clock.now() + delay

    def recv(self, timeout: float) -> bytes:
        wait = self._ready - self.clock.now() if self._reply else timeout
        if wait > timeout or not self._reply:
            self.clock.sleep(timeout)
            return b""
        if wait > 0:
            self.clock.sleep(wait)
        data, self._reply = self._reply, b""
        return data


@contextmanager
def open_drives(resolved: Resolved, units: list[int] | None = None, trace: Trace | None = None,
                notice: Callable[[str], None] | None = None) -> Iterator[list[Drive]]:
    """Open the link (to the embedded simulator for --port sim) and yield one Drive per unit."""
    from servotool.files import sim_state_dir
    from servotool.ops.journal import recover_at_start

    units = units or [resolved.unit]
    wire = None
    settings = resolved.settings
    # The name the host's journal and write lock know this bus by (a simulator by its state folder).
    port = f"sim:{sim_state_dir().resolve()}" if resolved.simulated else settings.port
    if resolved.simulated:
        from servotool.sim.firmware import build_drive
        from servotool.sim.line import Line

        wire = SimWire(Line([build_drive(resolved.profile, u) for u in units]))
        (notice or _stderr)(sim_notice(resolved, units))
    elif (advice := latency_advice(settings.port)) and settings.port not in _ADVISED:
        _ADVISED.add(settings.port)             # once a run, however many times the port opens
        (notice or _stderr)(f"servotool: warning: {advice}")
    link = ModbusLink(settings, trace=trace, wire=wire)
    try:
        drives = [Drive(link, resolved.profile, u, port=port) for u in units]
        # Before anything is written: the drive answering must be the one the profile describes. The embedded
        # simulator is built from the profile itself.
        if resolved.identity_check and not resolved.simulated:
            from servotool.ops.identity import confirm, warning_text

            if text := warning_text(confirm(drives)):
                (notice or _stderr)(f"servotool: warning: {text}")
        for d in drives:      # what a killed servotool process left on these drives is put right first
            recover_at_start(d, notice or _stderr, (sim_state_dir(),) if wire else ())
        yield drives
    finally:
        link.close()


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)
