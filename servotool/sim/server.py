"""Serve simulated drives as Modbus RTU slaves: RTU over TCP with pymodbus' server, a serial line with
sim/serial.py's framing.

The only module of the simulator that touches pymodbus.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

from pymodbus import FramerType
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import NoSuchIdException
from pymodbus.pdu import DecodePDU, ExceptionResponse, ModbusPDU
from pymodbus.server import ModbusTcpServer
from pymodbus.simulator import DataType, SimData, SimDevice

from servotool.clock import RealClock
from servotool.errors import DeviceError
from servotool.link.ports import parse_tcp, port_problem
from servotool.model.profile import LineSettings, Profile
from servotool.sim.device import SimulatedDrive
from servotool.sim.firmware import build_drive
from servotool.sim.line import WRITE_CODES, Line, env_choice, refusal

if TYPE_CHECKING:  # the bad-line proxy loads only when faults are asked for (not for a plain --port sim)
    from servotool.sim.faults import FaultProxy, LineFaults


logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


class _Datastore:
    """The line as the server's datastore (pymodbus calls it with each decoded request); a unit nobody serves stays
    silent. pymodbus' own (SimCore) would first map every register between the lowest address and the highest (5 ms
    of each DSX7E start, 20 ms of an IS620P one) for checks the drive makes anyway, and answers unknown ids with
    exception 04."""

    def __init__(self, line: Line) -> None:
        self.line = line
        self._written: dict[tuple[int, int], list[int]] = {}

    def device_ids(self) -> list[int]:
        return list(self.line.drives)

    def _known(self, device_id: int) -> SimulatedDrive:
        if (drive := self.line.drives.get(device_id)) is None:
            raise NoSuchIdException(f"unit {device_id}")
        return drive

    async def async_getValues(self, device_id: int, func_code: int, address: int, count: int = 1):
        drive = self._known(device_id)
        if func_code in WRITE_CODES:  # pymodbus reads a single write back for its reply: what was written
            return self._written.pop((device_id, address), [0] * count)
        return await self._serve(drive, func_code, address, count, None)

    async def async_setValues(self, device_id: int, func_code: int, address: int, values: list[int]):
        drive = self._known(device_id)
        written = [int(v) for v in values]
        if isinstance(result := await self._serve(drive, func_code, address, len(written), written), ExcCodes):
            return result
        if func_code == 6:
            self._written[(device_id, address)] = written
        return None

    async def _serve(
        self, drive: SimulatedDrive, fc: int, address: int, count: int, values: list[int] | None
    ) -> list[int] | ExcCodes:
        arrived = _CLOCK.now()  # the drive's own work (the plant's integration) happens within the wire time
        result, delay = self.line.serve(drive, fc, address, count, values)
        if result is None:  # the drive hears garbage at this speed: no answer, as from a unit nobody serves
            raise NoSuchIdException(f"unit {drive.unit} listens at another speed")
        if isinstance(result, int):
            return ExcCodes(result)
        if delay:
            await _wait_until(arrived + delay)
        return result


# asyncio's timers wake on the selector's whole milliseconds (epoll rounds a timeout up): a wait on them alone comes
# up to a millisecond late, as much as a request's whole wire time at 115200 baud. The last of it is slept on this
# thread instead (the line carries one frame at a time: nothing else is due on it meanwhile).
COARSE_TIMER_S = 0.0015
_CLOCK = RealClock()  # a served line runs on real time (the one clock module: tests/test_clock.py)


async def _wait_until(end: float) -> None:
    """Wait until `end` (the real clock's now), to within the OS's sleep precision rather than the event loop's
    tick."""
    if (coarse := end - _CLOCK.now() - COARSE_TIMER_S) > 0:
        await asyncio.sleep(coarse)
    if (left := end - _CLOCK.now()) > 0:
        _CLOCK.sleep(left)


class _Refusal(ModbusPDU):
    """A request the slave refuses before touching any register: answered with exception `code`."""

    def __init__(self, function_code: int, code: int) -> None:
        super().__init__()
        self.function_code, self.code = function_code, code

    async def datastore_update(self, context: _Datastore, device_id: int) -> ModbusPDU:  # type: ignore[override]
        context._known(device_id)
        return ExceptionResponse(self.function_code, self.code)


class _SpecDecoder(DecodePDU):
    """Request decoding as the Modbus specification has a slave do it (sim.line.refusal): pymodbus 3.16 answers
    a function the drive lacks or a quantity out of range with the malformed `ID 80 01`, or with 02 at unmapped
    addresses."""

    def __init__(self, answered: frozenset[int]) -> None:
        super().__init__(True)
        self.answered = answered

    def decode(self, frame: bytes) -> ModbusPDU | None:
        fc = frame[0] if frame else 0
        if fc & 0x80:
            return None
        if (code := refusal(frame, self.answered)) is not None:
            return _Refusal(fc, code)
        return super().decode(frame)


async def _start(port: str, served: Line, trace: Callable[[bool, bytes], None] | None):
    """pymodbus' RTU-over-TCP server for the drives on a tcp://HOST:PORT spec, started, answering as `served` has it."""
    # The server wants a datastore to start with; the line takes its place below.
    devices = [SimDevice(id=unit, simdata=[SimData(address=0, datatype=DataType.UINT16)]) for unit in served.drives]

    def hook(sending: bool, data: bytes) -> bytes:
        if trace:
            trace(sending, data)
        return data

    tcp = parse_tcp(port)
    assert tcp is not None, "a serial line is framed by sim/serial.py"
    try:  # pymodbus says only 'Could not start listen': bind once here, where the cause gets named
        socket.create_server(tcp).close()
    except OSError as exc:
        raise DeviceError(f"cannot serve on {port}: {port_problem(port, exc)}") from None
    # A real RS485 slave stays silent for other unit ids, so missing devices get no answer.
    server = ModbusTcpServer(
        devices,
        framer=FramerType.RTU,
        address=tcp,
        trace_packet=hook if trace else None,
        ignore_missing_devices=True,
        broadcast_enable=True,  # unit 0: applied by every drive, unanswered
    )
    server.context = _Datastore(served)  # type: ignore[assignment]
    server.decoder = _SpecDecoder(served.answered)
    try:
        await server.serve_forever(background=True)
    except Exception as exc:  # OSError, RuntimeError
        raise DeviceError(f"cannot serve on {port}: {port_problem(port, exc)}") from None
    return server


def bound_port(server: ModbusTcpServer) -> int:
    """The TCP port a server listens on (useful after binding port 0)."""
    return int(server.transport.sockets[0].getsockname()[1])  # type: ignore[union-attr]


def serve_forever(
    port: str,
    drives: list[SimulatedDrive],
    line: LineSettings | None = None,
    trace: Callable[[bool, bytes], None] | None = None,
    ready: Callable[[str, Line], None] | None = None,
    faults: LineFaults | None = None,
    choice: str | int | None = None,
) -> None:
    """Serve in the foreground until interrupted; with faults, behind a bad line on the tcp:// port. The answers
    are timed as on the line the drives are set to (`line`, else their profile's) unless `choice`, their own
    setting or SERVOTOOL_SIM_LINE_BAUD says otherwise (line.emulated); on a serial port, by the port itself. A
    serial port is framed by sim/serial.py (the 3.5-character rule pymodbus' framer cannot keep), RTU over TCP by
    pymodbus."""
    tcp = parse_tcp(port)
    if faults is not None and not tcp:
        raise DeviceError(f"cannot serve on {port}: line faults need a tcp://HOST:PORT port")
    served = Line(drives, threading.Lock(), line, choice, wired=not tcp, default=env_choice())
    if not tcp:
        from servotool.sim.serial import SerialSlave

        slave = SerialSlave(port, served, line or LineSettings(), trace)
        slave.serve(ready=(lambda: ready(port, served)) if ready else None)
        return

    stopped_by: list[int] = []

    async def main() -> None:
        proxy = None
        server = await _start("tcp://127.0.0.1:0" if faults else port, served, trace)
        _stop_on_termination(server, stopped_by)
        bound = bound_port(server) if tcp else 0
        if faults is not None and tcp:
            from servotool.sim.faults import FaultProxy

            proxy = FaultProxy(("127.0.0.1", bound), faults)
            try:
                bound = await proxy.start(*tcp)
            except OSError as exc:
                raise DeviceError(f"cannot serve on {port}: {port_problem(port, exc)}") from None
        if ready:
            ready(f"{port[:-2]}:{bound}" if tcp and port.endswith(":0") else port, served)
        try:
            await server.serving
        finally:
            if proxy:
                await proxy.close()
            await server.shutdown()

    asyncio.run(main())
    if stopped_by:  # a terminate signal ends it as Ctrl-C does (exit 130, "simulator stopped")
        raise KeyboardInterrupt


def _stop_on_termination(server: ModbusTcpServer, stopped_by: list[int]) -> None:
    """SIGTERM and SIGHUP end the serving through the event loop's own signal handling (POSIX), as asyncio.run
    already ends it at Ctrl-C: the CLI's handler would raise KeyboardInterrupt wherever the loop happened to be, inside
    a transport's or a request's callback, and the loop's shutdown could then wait on what that callback never
    finished (a test's terminate once went unanswered for 10 s). Windows has no loop signal handlers: the CLI's
    handler stays there."""
    import signal

    loop = asyncio.get_running_loop()

    def stop(number: int) -> None:
        stopped_by.append(number)
        if not server.serving.done():
            server.serving.set_result(True)

    for name in ("SIGTERM", "SIGHUP"):
        number = getattr(signal, name, None)
        if number is None:
            continue
        try:
            loop.add_signal_handler(number, stop, number)
        except (NotImplementedError, RuntimeError, ValueError):  # Windows; not the main thread
            return


def serve_units(
    port: str,
    profile: Profile,
    units: list[int],
    line: LineSettings,
    *,
    line_baud: str | int | None = None,
    trace: Callable[[bool, bytes], None] | None = None,
    ready: Callable[[str, Line, dict[int, list[str]]], None] | None = None,
    faults: LineFaults | None = None,
) -> None:
    """Serve simulated drives of one profile in the foreground until interrupted. Starting them switches them on:
    ready(where, line, took) gets, by unit, the codes whose pending power-cycle change took effect. line_baud
    overrides the drives' own line emulation for this run; faults put them behind a bad line."""
    drives = [build_drive(profile, u) for u in units]
    took = {d.unit: d.power_cycle() for d in drives}
    serve_forever(
        port,
        drives,
        line,
        trace,
        ready=(lambda where, served: ready(where, served, took)) if ready else None,
        faults=faults,
        choice=line_baud,
    )


class EmbeddedSim:
    """Simulated drives served on a loopback TCP port from a background thread (`--port sim`); with faults, the
    port is a bad line in front of them (`self.proxy` changes what it does).

    Each answer comes after its wire time on the line the drives are reached at (`line`, else each one's
    profile's factory settings), as a real RS485 line has it, unless the drive's own `sim config --line-baud` or
    SERVOTOOL_SIM_LINE_BAUD says otherwise (`self.line.describe()` says which)."""

    def __init__(
        self, drives: list[SimulatedDrive], faults: LineFaults | None = None, line: LineSettings | None = None
    ) -> None:
        self.drives = drives
        self.lock = threading.Lock()
        self.line = Line(drives, self.lock, line, default=env_choice())
        self.line.host = line
        self._loop = asyncio.new_event_loop()
        self.proxy: FaultProxy | None = None
        # Started on this thread, before the loop's own thread runs it: a wait for that thread at each step of
        # the start would cost a scheduling round trip each on a busy machine.
        try:
            self._server: ModbusTcpServer | None = self._loop.run_until_complete(
                _start("tcp://127.0.0.1:0", self.line, None)
            )
            port = bound_port(self._server)
            self.direct_port = f"tcp://127.0.0.1:{port}"  # the drives themselves, behind any bad line
            if faults is not None:
                from servotool.sim.faults import FaultProxy

                self.proxy = FaultProxy(("127.0.0.1", port), faults)
                port = self._loop.run_until_complete(self.proxy.start())
        except BaseException:
            self._loop.close()
            raise
        self.port = f"tcp://127.0.0.1:{port}"
        self._thread = threading.Thread(target=self._loop.run_forever, name="servotool-sim", daemon=True)
        self._thread.start()

    def host_speaks(self, line: LineSettings) -> None:
        """The master now speaks at these settings (its own set_line): a drive whose baud entry set another speed
        stays silent."""
        self.line.host = line

    async def _stop(self) -> None:
        try:
            if self.proxy is not None:
                await self.proxy.close()
                self.proxy = None
            if self._server is not None:
                await self._server.shutdown()
                self._server = None
        finally:
            # After the callbacks the shutdown scheduled (its connections' ends), not before them.
            self._loop.call_soon(self._loop.stop)

    def close(self) -> None:
        """Shut the server down and stop its thread: one request to that thread, one wait for it to end."""
        if not self._thread.is_alive():
            return
        done = asyncio.run_coroutine_threadsafe(self._stop(), self._loop)
        self._thread.join(timeout=5)
        if done.done():
            done.result()  # a failure to shut down is raised, as before
