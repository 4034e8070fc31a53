"""A JOG trigger that is a forced digital input (profile forced_inputs: SD25 So-57/So-58).

While forcing is on, every input level comes from the forced value alone (SD25 section 7.10.9, L5249-5262): a wired
E-stop or limit switch on a DI is ignored. So before forcing, the wired levels are read and every input but the
trigger's is held at its level in the forced value; where the profile says the monitor still shows the terminals,
it is watched at each beat and a change stops the motion; and forcing is released on every exit (journaled first, so
that after a kill -9 the next command releases it before anything else, ops.journal).
"""

from __future__ import annotations

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.errors import DeviceError
from servotool.model.forcing import is_forcing, switch_value, trigger_bits
from servotool.model.profile import Profile
from servotool.ops import journal


class InputsChanged(DeviceError):
    """A wired input changed while the drive's inputs were forced: the motion was stopped."""


def wired_inputs_warning(profile: Profile) -> str | None:
    """The one line said before a motion on a forced-input drive, None elsewhere."""
    spec = profile.forced_inputs
    if spec is None:
        return None
    watched = (
        "servotool watches the input monitor and stops on a change"
        if spec.monitor_shows == "terminals"
        else f"{spec.monitor_code} shows the forced levels then, so servotool cannot see them"
    )
    return (
        f"while it moves the drive's inputs are forced ({spec.switch_code}): wired inputs (E-stop, limit switches "
        f"on a DI) are IGNORED ({watched}); main power still stops the motor"
    )


class ForcedInputs:
    """The forcing of one motion: on (engage) with every non-trigger input held at its wired level, the trigger's
    levels for a direction (levels), the watch, and off again (release)."""

    def __init__(self, drive: Drive, clock: Clock, beat_s: float) -> None:
        p = drive.profile
        spec = p.forced_inputs
        assert spec is not None
        self.drive, self.clock, self.beat_s = drive, clock, beat_s
        self.switch = p.entry(spec.switch_code)
        self.forced = p.entry(spec.levels_code)
        self.monitor = p.entry(spec.monitor_code)
        self.watching = spec.monitor_shows == "terminals"
        self.trigger = trigger_bits(p)
        self.held: int | None = None  # the non-trigger levels held while forcing is on (None: not forcing)
        self._switch_raw = 0
        self._forced_original = 0
        self._watched_at = clock.now()

    @property
    def engaged(self) -> bool:
        return self.held is not None

    def engage(self) -> None:
        """Forcing on, every input but the trigger's held at the level its terminal has now. Forcing found on (left
        by someone) is released first, so that the monitor shows the terminals."""
        if self.engaged:
            return
        switch, forced = self.drive.read_entries([self.switch, self.forced])
        self._switch_raw, self._forced_original = switch.raw, forced.raw
        released = switch_value(self.drive.profile, switch.raw, False)
        journal.note_forcing(self.drive, self.switch.code, released, self.forced.code, forced.raw)
        if is_forcing(self.drive.profile, switch.raw):
            self.drive.write_raw(self.switch, released)
        wired = self.drive.read_entries([self.monitor])[0].raw
        self.held = wired & ~self.trigger
        self.drive.write_raw(self.forced, self.held)
        self.drive.write_raw(self.switch, switch_value(self.drive.profile, switch.raw, True))
        self._watched_at = self.clock.now()

    def levels(self, trigger: int) -> int:
        """The forced value that asserts these trigger bits (0: stop) with every other input as held."""
        return (self.held or 0) | trigger

    def watch(self) -> None:
        """At most once a beat, where the monitor shows the terminals: InputsChanged when an input other than the
        trigger's differs from the level held."""
        if not self.watching or self.held is None or self.clock.now() - self._watched_at < self.beat_s:
            return
        self._watched_at = self.clock.now()
        now = self.drive.read_entries([self.monitor])[0].raw & ~self.trigger
        if now != self.held:
            changed = now ^ self.held
            names = [self.monitor.bits.get(b, f"bit {b}") for b in range(16) if changed >> b & 1]
            raise InputsChanged(
                f"wired input {', '.join(names)} changed while the drive's inputs were forced "
                f"({self.monitor.code} {self.held:#x} -> {now:#x}): motion stopped"
            )

    def release(self) -> None:
        """Forcing off (every input follows its terminal again) and the forced value put back; the journal record
        goes. Safe to call when not engaged."""
        if self.held is None:
            return
        self.drive.write_raw(self.switch, switch_value(self.drive.profile, self._switch_raw, False))
        self.held = None
        if self.drive.read_entries([self.forced])[0].raw != self._forced_original:
            self.drive.write_raw(self.forced, self._forced_original)
        journal.clear_forcing(self.drive)
