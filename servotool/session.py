"""Opening drives for a resolved connection (a Bus: the link, the embedded simulator for --port sim, each unit's
identity checked once), and finding the profile of a drive on a real port when none is given."""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import replace
from typing import TYPE_CHECKING

from servotool.connection import SIM_PORT, ConnectOptions, Resolved, effective, merge, resolve
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.link.master import RtuMaster
from servotool.link.ports import Trace, bus_identity, latency_advice

if TYPE_CHECKING:
    from servotool.ops.scan import Found

_ADVISED: set[str] = set()


def resolve_or_find(options: ConnectOptions, trace: Trace | None = None) -> tuple[Resolved, Found | None]:
    """The options resolved (connection.resolve); on a real port without a profile, the profile found first: the
    unit's answers to every shipped profile's identity checks, read once (ops.scan.find), must fit exactly one
    (ProfileNotFound otherwise). That reading is the unit's identity check: open_drives does not repeat it.
    Returns what was found (None when the profile was given or the port is the simulator)."""
    opts = effective(options)
    if opts.profile or not opts.port or opts.port == SIM_PORT:
        return resolve(options), None
    from servotool.ops.identity import choose, shipped_profiles
    from servotool.ops.scan import find

    candidates = shipped_profiles()
    defaults = sorted({p.default_unit for p in candidates})
    unit = opts.unit if opts.unit is not None else defaults[0]
    found = find(options, unit, candidates, trace=trace)
    picked = choose(list(found.ranked), found.port)
    line = found.line
    given = ConnectOptions(
        profile=picked.profile.id,
        unit=unit,
        baud=line.baud if line else None,
        parity=line.parity if line else None,
        stopbits=line.stopbits if line else None,
    )
    resolved = resolve(merge(options, given))
    return replace(resolved, confirmed=frozenset({unit})), found


def sim_notice(resolved: Resolved, units: list[int], timing: str) -> str:
    """The banner of the embedded simulator: which drive, and whether its line is emulated ('line emulated at
    9600 baud 8N1', 'line NOT emulated: fast')."""
    ids = ",".join(str(u) for u in units)
    return f"servotool: SIMULATED drive {resolved.profile.id} unit{'s' if len(units) > 1 else ''} {ids}, {timing}"


class Bus:
    """A port opened for one command (open_drives) or for many (`servotool shell`): the link, with the embedded
    simulator started for --port sim; each unit's identity checked the first time its drive is asked for, and
    what a killed servotool process left on a drive put right before each command has it."""

    def __init__(
        self,
        resolved: Resolved,
        units: list[int] | None = None,
        trace: Trace | None = None,
        notice: Callable[[str], None] | None = None,
    ) -> None:
        self.resolved, self.notice = resolved, notice or _stderr
        self.units = units or [resolved.unit]
        self.sim = None
        settings = resolved.settings
        # The name the host's journal and write lock know this bus by, whatever its spelling (a simulated drive by its
        # state folder and profile: each profile's simulated drive is a drive of its own).
        self.port = sim_bus(resolved.profile.id) if resolved.simulated else bus_identity(settings.port)
        if resolved.simulated:
            from servotool.sim.firmware import build_drive
            from servotool.sim.server import EmbeddedSim

            self.sim = EmbeddedSim([build_drive(resolved.profile, u) for u in self.units], line=settings.line)
            settings = replace(settings, port=self.sim.port)
            self.notice(sim_notice(resolved, self.units, self.sim.line.describe()))
        elif (advice := latency_advice(settings.port)) and settings.port not in _ADVISED:
            _ADVISED.add(settings.port)  # once a run, however many times the port opens
            self.notice(f"servotool: warning: {advice}")
        try:
            self.link = RtuMaster(settings, trace=trace)
        except Exception:
            if self.sim:
                self.sim.close()
            raise
        if self.sim:  # the simulated drives hear the speed the master speaks (a line boost changes it)
            self.link.line_listeners.append(self.sim.host_speaks)
        self.checked: set[int] = set(resolved.confirmed)

    def drives(self, units: list[int] | None = None, bare: bool = False) -> list[Drive]:
        """A Drive for each unit (the bus's own by default), on this link; UsageError for a unit the embedded
        simulator does not serve. bare: nothing read or written first, neither a raised line nor the identity put
        right nor a journal (`servotool stop`: nothing may fail before its first write); the next command does
        them."""
        from servotool.files import sim_state_dir
        from servotool.ops.journal import boost_record, recover_at_start

        units = units or self.units
        if self.sim and (others := [u for u in units if u not in self.units]):
            served = ",".join(map(str, self.units))
            raise UsageError(f"the simulated drives here are unit {served}, not {','.join(map(str, others))}")
        drives = [Drive(self.link, self.resolved.profile, u, port=self.port) for u in units]
        line = self.link.control_line()
        for d in drives:  # one line for the bus: a relay per adapter, wired to every drive's enable or contactor
            d.heartbeat_line, d.heartbeat_timeout_s = line, self.resolved.heartbeat_timeout_s
        if bare:
            return drives
        unchecked = [d for d in drives if d.unit not in self.checked]
        raised = self.resolved.profile.boost.available and any(boost_record(d) for d in unchecked)
        if raised:  # a line a killed process left raised comes first (ops.boost loads only then)
            from servotool.ops.boost import recover_boost

            recover_boost(unchecked, self.notice)
        # Before anything is written: the drive answering must be the one the profile describes. The embedded
        # simulator is built from the profile itself.
        if self.resolved.identity_check and not self.resolved.simulated and unchecked:
            from servotool.ops.identity import confirm, warning_text
            from servotool.ops.journal import know_identity

            verdicts = confirm(unchecked)
            for d, verdict in zip(unchecked, verdicts, strict=True):  # the journal's records name the drive by them
                know_identity(d, {a.check.code: a.raw for a in verdict.answers if a.check.code and a.raw is not None})
            if text := warning_text(verdicts):
                self.notice(f"servotool: warning: {text}")
        self.checked.update(units)
        for d in drives:  # what a killed servotool process left on these drives is put right first
            recover_at_start(d, self.notice, (sim_state_dir(),) if self.sim else ())
        return drives

    def close(self) -> None:
        try:
            self.link.close()
        finally:
            if self.sim:
                self.sim.close()


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
    bus = Bus(resolved, units, trace, notice)
    try:
        yield bus.drives(bare=bare)
    finally:
        bus.close()


def sim_bus(profile_id: str) -> str:
    """The bus name (Drive.port) of `--port sim`: the simulator's state folder and the profile, since each
    profile's simulated drive is a drive of its own."""
    from servotool.files import sim_state_dir

    return f"sim:{sim_state_dir().resolve()}#{profile_id}"


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)
