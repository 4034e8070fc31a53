"""Opening drives for a resolved connection, starting the embedded simulator for --port sim."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace

from servotool.connection import Resolved
from servotool.drive import Drive
from servotool.link.master import RtuMaster
from servotool.link.ports import Trace, latency_advice

_ADVISED: set[str] = set()


def sim_notice(resolved: Resolved, units: list[int]) -> str:
    ids = ",".join(str(u) for u in units)
    return (
        f"servotool: SIMULATED drive ({resolved.profile.model} profile '{resolved.profile.id}', unit {ids}); "
        f"no real hardware is involved"
    )


@contextmanager
def open_drives(
    resolved: Resolved,
    units: list[int] | None = None,
    trace: Trace | None = None,
    notice: Callable[[str], None] | None = None,
    bare: bool = False,
) -> Iterator[list[Drive]]:
    """Open the link (starting the embedded simulator for --port sim) and yield one Drive per unit. bare: no
    identity check and no journal recovery first (`servotool stop`: nothing may fail before its first write)."""
    from servotool.files import sim_state_dir
    from servotool.ops.journal import recover_at_start

    units = units or [resolved.unit]
    sim = None
    settings = resolved.settings
    # The name the host's journal and write lock know this bus by (a simulator by its state folder).
    port = f"sim:{sim_state_dir().resolve()}" if resolved.simulated else settings.port
    if resolved.simulated:
        from servotool.sim.firmware import build_drive
        from servotool.sim.server import EmbeddedSim

        sim = EmbeddedSim([build_drive(resolved.profile, u) for u in units])
        settings = replace(settings, port=sim.port)
        (notice or _stderr)(sim_notice(resolved, units))
    elif (advice := latency_advice(settings.port)) and settings.port not in _ADVISED:
        _ADVISED.add(settings.port)  # once a run, however many times the port opens
        (notice or _stderr)(f"servotool: warning: {advice}")
    try:
        link = RtuMaster(settings, trace=trace)
    except Exception:
        if sim:
            sim.close()
        raise
    try:
        drives = [Drive(link, resolved.profile, u, port=port) for u in units]
        # Before anything is written: the drive answering must be the one the profile describes. The embedded
        # simulator is built from the profile itself.
        if resolved.identity_check and not resolved.simulated and not bare:
            from servotool.ops.identity import confirm, warning_text

            if text := warning_text(confirm(drives)):
                (notice or _stderr)(f"servotool: warning: {text}")
        for d in [] if bare else drives:  # what a killed servotool process left on these drives is put right first
            recover_at_start(d, notice or _stderr, (sim_state_dir(),) if sim else ())
        yield drives
    finally:
        link.close()
        if sim:
            sim.close()


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)
