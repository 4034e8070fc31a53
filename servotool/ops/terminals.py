"""The drive's digital inputs and outputs as it keeps them: each terminal's level and assigned function.

The levels come from the profile's input and output monitors (one coalesced read a sample); the functions from
the drive's own assignment parameters, read once, decoded through the profile's function table. A function the
manual does not name is shown by its number and why it has no name, never guessed.
"""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import format_value, part_value
from servotool.model.profile import Entry, Profile
from servotool.model.terminals import Terminal, TerminalGroup, split_part


@dataclass(frozen=True)
class Assignment:
    """What gives one terminal its function, as read from the drive (once: changes act after a power cycle)."""

    terminal: Terminal
    number: int | None  # the function number read (None: a fixed function)
    function: str  # its name and meaning as the manual gives them, or why there is none
    named: bool  # whether the manual names it
    set_by: str  # the entry (and field) read, or "fixed"
    logic: str  # the logic setting as the drive holds it ("" where the profile maps none)
    unverified: str  # what the manual leaves open about this terminal and its function
    unnamed: str = ""  # why the manual names no function for this number

    def as_json(self) -> dict[str, object]:
        return {
            "terminal": self.terminal.name,
            "function": self.function,
            "function_number": self.number,
            "named_by_manual": self.named,
            "why_not_named": self.unnamed or None,
            "set_by": self.set_by,
            "logic": self.logic or None,
            "note": self.terminal.note or None,
            "unverified": self.unverified or None,
        }


@dataclass(frozen=True)
class Levels:
    """One reading of the monitors: terminal name -> level (0/1), per group."""

    inputs: dict[str, int]
    outputs: dict[str, int]

    def of(self, direction: str) -> dict[str, int]:
        return self.inputs if direction == "inputs" else self.outputs


class TerminalReader:
    """Reads a drive's terminals: the assignments once, the levels on every call."""

    def __init__(self, drive: Drive) -> None:
        io = drive.profile.io
        if io is None or not io.groups:
            self.refuse(drive.profile)
        self.drive = drive
        self.groups: tuple[TerminalGroup, ...] = io.groups
        self._monitors = [drive.profile.entry(g.monitor) for g in self.groups]
        self.assignments: dict[str, list[Assignment]] = {}

    def read_assignments(self) -> dict[str, list[Assignment]]:
        """Every terminal's function as the drive's parameters assign it, in one coalesced read."""
        profile = self.drive.profile
        wanted: dict[str, Entry] = {}
        for g in self.groups:
            for t in g.terminals:
                for ref in (t.function, t.logic):
                    if ref:
                        entry = profile.entry(split_part(ref)[0])
                        wanted[entry.code] = entry
        raw = {r.entry.code: r.raw for r in self.drive.read_entries(list(wanted.values()))}
        self.assignments = {g.direction: [_assignment(g, t, raw, profile) for t in g.terminals] for g in self.groups}
        return self.assignments

    @staticmethod
    def refuse(profile: Profile) -> None:
        raise UsageError(
            f"profile {profile.id} maps no digital inputs or outputs (no 'io' section): monitor --io cannot show them"
        )

    @property
    def monitors(self) -> list[Entry]:
        """The monitor entries whose bits are the levels (what a sample reads)."""
        return list(self._monitors)

    def read_levels(self) -> Levels:
        """Each terminal's level from the monitors, in one coalesced read."""
        return self.levels({r.entry.code: r.raw for r in self.drive.read_entries(self._monitors)})

    def levels(self, raw: dict[str, int | float]) -> Levels:
        """The levels in the monitors' raw values (code -> raw)."""
        by_group = {g.direction: {t.name: int(raw[g.monitor]) >> t.bit & 1 for t in g.terminals} for g in self.groups}
        return Levels(by_group.get("inputs", {}), by_group.get("outputs", {}))


def _value(profile: Profile, ref: str, raw: dict[str, int]) -> tuple[Entry, int]:
    """CODE or CODE.PART's value among the raw values read."""
    code, part = split_part(ref)
    entry = profile.entry(code)
    return entry, part_value(entry, raw[entry.code], part)


def _assignment(group: TerminalGroup, t: Terminal, raw: dict[str, int], profile: Profile) -> Assignment:
    doubts = [d for d in (t.unverified,) if d]
    logic = ""
    if t.logic:
        entry, value = _value(profile, t.logic, raw)
        logic = f"{t.logic} = {value}" if "." in t.logic else f"{t.logic} = {format_value(entry, value)}"
    if t.fixed is not None:
        if t.fixed.unverified:
            doubts.append(t.fixed.unverified)
        return Assignment(t, None, t.fixed.label, True, "fixed", logic, "; ".join(doubts))
    number = _value(profile, t.function, raw)[1]
    function = group.function(t, number)
    if function is None:
        why = group.unlisted or "not named in the manual"
        return Assignment(t, number, f"{number}, not named", False, t.function, logic, "; ".join(doubts), why)
    text = f"{number} {function.label}"
    if function.unverified:
        doubts.append(function.unverified)
        text += " (unverified)"
    return Assignment(t, number, text, True, t.function, logic, "; ".join(doubts))
