"""One action on every drive of an inventory: a worker thread per bus, one request at a time on each bus (as RS485
has it), all buses at once; a failure on one drive or bus leaves the others to finish.

Threads, not processes: a bus's work is waiting on its line (a reply at 9600 baud takes tens of milliseconds, its
framing a fraction of one), and the waits release the GIL; threads share the one progress display, the result
table and the process's per-bus write locks without start-up cost or messages between processes. Each bus is one
thread's alone (ops.journal's lock counts its holders per process, not per thread): the inventory lists a bus once.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from typing import Any, Protocol

from servotool.clock import Clock, RealClock
from servotool.connection import ConnectOptions, merge
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.fleet.inventory import BusSpec, Inventory, Target

FAILED = "failed"
EXIT_FAILED = 5  # some drive failed; the others were done (README: Exit codes)


@dataclass
class DriveOutcome:
    """What the action did on one drive: a status word (saved, unchanged, equal, differs, changed, would change,
    failed), one line for a table, and its facts for JSON."""

    machine: str
    bus: str
    port: str
    unit: int
    profile: str | None = None
    status: str = FAILED
    detail: str = ""
    data: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    exit_code: int = 0  # the failure's (1 device, 2 usage, 3 verify); 0 when it did not fail
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        return self.status == FAILED

    def as_json(self) -> dict[str, Any]:
        return {
            "machine": self.machine,
            "bus": self.bus,
            "port": self.port,
            "unit": self.unit,
            "profile": self.profile,
            "status": self.status,
            "detail": self.detail,
            "error": self.error,
            "exit_status": self.exit_code,
            "time": {"value": round(self.seconds, 3), "unit": "s"},
            **self.data,
        }


@dataclass
class BusOutcome:
    spec: BusSpec
    drives: list[DriveOutcome]
    seconds: float = 0.0
    error: str | None = None  # the bus could not be opened: every drive failed with it

    def as_json(self) -> dict[str, Any]:
        return {
            "machine": self.spec.machine,
            "bus": self.spec.name,
            "port": self.spec.port,
            "units": self.spec.units,
            "error": self.error,
            "time": {"value": round(self.seconds, 3), "unit": "s"},
        }


@dataclass
class FleetResult:
    action: str
    buses: list[BusOutcome]
    seconds: float

    @property
    def drives(self) -> list[DriveOutcome]:
        return [d for b in self.buses for d in b.drives]

    def counts(self) -> dict[str, int]:
        found: dict[str, int] = {}
        for d in self.drives:
            found[d.status] = found.get(d.status, 0) + 1
        return dict(sorted(found.items()))


@dataclass(frozen=True)
class Event:
    """Progress: 'bus' (its drives are being opened), 'drive' (one starts), 'done' (one ended, with its outcome),
    'notice' (a line the bus has to say), 'bus_done'."""

    kind: str
    spec: BusSpec
    unit: int | None = None
    outcome: DriveOutcome | None = None
    text: str = ""


class Action(Protocol):
    """What a fleet command does on each drive."""

    name: str

    def on_bus(self, drives: list[Drive], spec: BusSpec, notice: Callable[[str], None]) -> AbstractContextManager[Any]:
        """Around a bus's drives (a raised line for a long read), or nullcontext."""
        ...

    def on_drive(self, drive: Drive, target: Target, spec: BusSpec) -> tuple[str, str, dict[str, Any]]:
        """(status, one line, facts) for one drive; a ServoError marks it failed."""
        ...


def run(
    inventory: Inventory,
    action: Action,
    *,
    jobs: int | None = None,
    events: Callable[[Event], None] | None = None,
    clock: Clock | None = None,
    stop: threading.Event | None = None,
) -> FleetResult:
    """Run the action on every drive, each bus in a worker thread of its own (at most `jobs` at once); `events`
    hears progress from the workers' threads. `stop` set (Ctrl-C) lets each worker finish its drive and start no
    other: those are marked failed, 'not started'."""
    clock = clock or RealClock()
    say = events or (lambda _e: None)
    stop = stop or threading.Event()
    slots = threading.BoundedSemaphore(max(1, jobs or len(inventory.buses)))
    outcomes = [BusOutcome(spec, []) for spec in inventory.buses]
    start = clock.now()

    def worker(bus: BusOutcome) -> None:
        with slots:
            t0 = clock.now()
            try:
                _run_bus(bus, action, say, clock, stop)
            finally:
                bus.seconds = clock.now() - t0
                say(Event("bus_done", bus.spec))

    threads = [
        threading.Thread(target=worker, args=(b,), name=f"fleet-{b.spec.machine}-{b.spec.name}", daemon=True)
        for b in outcomes
    ]
    for t in threads:
        t.start()
    try:
        for t in threads:
            while t.is_alive():
                t.join(0.1)  # a Ctrl-C reaches the main thread between waits
    except KeyboardInterrupt:
        stop.set()
        for t in threads:
            t.join()
        raise
    return FleetResult(action.name, outcomes, clock.now() - start)


def _run_bus(
    bus: BusOutcome, action: Action, say: Callable[[Event], None], clock: Clock, stop: threading.Event
) -> None:
    """Open the bus, then each drive in turn; what fails is recorded, never raised."""
    from servotool.ops.changelog import origin
    from servotool.session import Bus, resolve_or_find

    spec = bus.spec

    def notice(text: str) -> None:
        say(Event("notice", spec, text=text))

    def outcome(unit: int) -> DriveOutcome:
        return DriveOutcome(spec.machine, spec.name, spec.port, unit, spec.options.profile)

    say(Event("bus", spec))
    with origin(machine=spec.machine):
        try:
            resolved, _found = resolve_or_find(merge(spec.options, ConnectOptions(unit=spec.units[0])))
            link = Bus(resolved, spec.units, notice=notice)
        except (ServoError, OSError) as exc:
            bus.error = str(exc)
            for target in spec.targets:
                failed = _failed(outcome(target.unit), exc)
                bus.drives.append(failed)
                say(Event("done", spec, target.unit, failed))
            return
        try:
            opened: list[tuple[Target, Drive | None, DriveOutcome]] = []
            for target in spec.targets:  # each unit's identity checked on its own: one wrong drive fails alone
                found = outcome(target.unit)
                found.profile = resolved.profile.id
                try:
                    [drive] = link.drives([target.unit])
                    opened.append((target, drive, found))
                except ServoError as exc:
                    opened.append((target, None, _failed(found, exc)))
            ready = [d for _t, d, _o in opened if d is not None]
            with action.on_bus(ready, spec, notice) if ready else nullcontext():
                for target, drive, found in opened:
                    if drive is not None:
                        _one(drive, target, spec, found, action, say, clock, stop)
                    bus.drives.append(found)
                    say(Event("done", spec, target.unit, found))
        except (ServoError, OSError) as exc:  # the bus's own wrapper (a raised line) failed
            bus.error = str(exc)
            done = {d.unit for d in bus.drives}
            for target in spec.targets:
                if target.unit not in done:
                    failed = _failed(outcome(target.unit), exc)
                    bus.drives.append(failed)
                    say(Event("done", spec, target.unit, failed))
        finally:
            link.close()


def _one(
    drive: Drive,
    target: Target,
    spec: BusSpec,
    found: DriveOutcome,
    action: Action,
    say: Callable[[Event], None],
    clock: Clock,
    stop: threading.Event,
) -> None:
    if stop.is_set():
        found.error = found.detail = "not started: interrupted"
        found.exit_code = 130
        return
    say(Event("drive", spec, target.unit))
    t0 = clock.now()
    try:
        found.status, found.detail, found.data = action.on_drive(drive, target, spec)
    except ServoError as exc:
        _failed(found, exc)
    except Exception as exc:  # a bug must not take the other drives and buses down with it
        found.status, found.exit_code = FAILED, 1
        found.error = found.detail = f"internal error: {type(exc).__name__}: {exc}"
    finally:
        found.seconds = clock.now() - t0


def _failed(found: DriveOutcome, exc: BaseException) -> DriveOutcome:
    found.status = FAILED
    found.error = found.detail = str(exc)
    found.exit_code = getattr(exc, "exit_code", 1)
    if hasattr(exc, "as_before"):  # ops.apply.ApplyFailed: whether the drive is as it was
        found.data = {"rolled_back": list(getattr(exc, "rolled_back", [])), "as_before": bool(exc.as_before)}
    return found


def exit_status(result: FleetResult, differ: Iterator[str] | tuple[str, ...] = ()) -> int:
    """0 when every drive is done (and none is in a `differ` status: differs, would change), 1 when one differs,
    EXIT_FAILED when one failed (the others were done)."""
    statuses = {d.status for d in result.drives}
    if FAILED in statuses:
        return EXIT_FAILED
    return 1 if statuses & set(differ) else 0
