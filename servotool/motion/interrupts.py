"""Interrupts while a motion is being stopped: they wait.

While a motion command runs (motion/stop.py: proven_on_interrupt, from before it says its bound to its end), the
first Ctrl-C / SIGTERM / SIGHUP (Ctrl-Break on Windows) raises KeyboardInterrupt as before; every later one is held
until the stop sequence, or its read-back, has run (motion/stop.py). timeout(1) signals the process
and then its group: the second SIGINT used to land inside the stop and leave SDC's servo on. Handlers are set only
in the main thread (signal's rule), so a motion in another thread runs unguarded.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType
from typing import NoReturn

INTERRUPT_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP", "SIGBREAK")


class InterruptGuard:
    """Signal handlers for the duration of a motion (main thread only; elsewhere nothing is installed).

    Armed, the first interrupt raises KeyboardInterrupt; then, and whenever disarmed, interrupts are held (counted)
    and the handler returns. Once one was raised, no enclosing section is armed again until the outermost ends: the
    rest of the command is its way out. `protected` code objects never see one raised: the stop's own entry
    points, where a signal can land before their first statement disarms."""

    def __init__(self) -> None:
        self.armed = False
        self.held = 0
        self.raised = 0  # interrupts raised since the outermost section started
        self._outer: list[tuple[bool, int]] = []  # each enclosing section's armed state, and the held count then
        self._previous: dict[int, object] = {}
        self.protected: set[object] = set()

    def enter(self, armed: bool = True) -> None:
        """A section starts (a motion: armed; a rollback: held): the outermost installs the handlers."""
        if not self._outer:
            self.held = self.raised = 0
            if threading.current_thread() is threading.main_thread():
                for name in INTERRUPT_SIGNALS:
                    number = getattr(signal, name, None)
                    if number is None:
                        continue
                    try:
                        self._previous[number] = signal.signal(number, self._handler)
                    except (OSError, ValueError):  # not settable here
                        pass
        self._outer.append((self.armed, self.held))
        self.armed = armed and not self.raised

    def leave(self) -> int:
        """A section ends: the outermost puts the previous handlers back. Returns the interrupts held during it."""
        armed, held_before = self._outer.pop()
        held = self.held - held_before
        self.armed = armed and not self.raised
        if not self._outer:
            for number, previous in self._previous.items():
                signal.signal(number, previous)  # type: ignore[arg-type]
            self._previous.clear()
            self.held = self.raised = 0
        return held

    def interrupt(self) -> KeyboardInterrupt:
        """The interrupt to raise now (one that came, or one held until now): every later one is held."""
        self.armed = False
        self.raised += 1
        return KeyboardInterrupt()

    def raise_interrupt(self) -> NoReturn:
        raise self.interrupt()

    def _handler(self, _signum: int, frame: FrameType | None) -> None:
        if self.armed and (frame is None or frame.f_code not in self.protected):
            self.raise_interrupt()
        self.held += 1


GUARD = InterruptGuard()


@contextmanager
def held_interrupts(raise_held: bool = True) -> Iterator[None]:
    """Run a short critical section (a rollback of gains) with every interrupt held; one that came is raised as
    KeyboardInterrupt after it (raise_held; not where an interrupt or failure is already on its way out)."""
    GUARD.enter(armed=False)
    try:
        yield
    finally:
        held = GUARD.leave()
    if held and raise_held:
        GUARD.raise_interrupt()
