"""A drive's digital inputs and outputs as its manual documents them (profile section `io`).

Each group (inputs, outputs) names the monitor entry whose bits give each terminal's level, the entry (or field of
one) that assigns each terminal its function, and the manual's function-code table; a terminal without an
assignment parameter has its one function fixed. What a manual leaves open (a bit layout, a function table it does
not print) is said with `unverified`, as for entries, so that a function is never named where the manual does not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

DIRECTIONS = ("inputs", "outputs")
# What drives a simulated output (sim.terminals): the simulated drive's own state, nothing the manual does not name.
SIM_OUTPUT_STATES = ("ready", "servo_on", "rotating", "zero_speed", "in_position", "alarm", "brake_released")


@dataclass(frozen=True)
class IoFunction:
    """One function a terminal can be given: the manual's short name and what it does."""

    name: str
    meaning: str = ""
    source: str = ""
    unverified: str = ""
    sim: str = ""  # outputs: the simulated drive's state that sets it (SIM_OUTPUT_STATES), "" for none

    @property
    def label(self) -> str:
        """'ALM, servo alarm', or the name alone."""
        return f"{self.name}, {self.meaning}" if self.meaning and self.meaning != self.name else self.name


@dataclass(frozen=True)
class Terminal:
    """One input or output terminal: its bit in the group's monitor, and what gives it its function."""

    name: str
    bit: int
    function: str = ""  # CODE or CODE.PART (a digit field or a bit name) holding the function number
    fixed: IoFunction | None = None  # a terminal with one function and no assignment parameter
    logic: str = ""  # CODE or CODE.PART setting the terminal's logic (shown as the drive holds it)
    special: dict[int, str] = field(default_factory=dict)  # a number's meaning on this terminal only
    note: str = ""
    source: str = ""
    unverified: str = ""


@dataclass(frozen=True)
class TerminalGroup:
    """The inputs or the outputs: the monitor, the terminals in bit order, the function-code table."""

    direction: str  # inputs | outputs
    monitor: str
    terminals: tuple[Terminal, ...]
    functions: dict[int, IoFunction]
    source: str
    unlisted: str = ""  # what to say of a function number the table lacks (why the manual names none)
    unverified: str = ""

    def function(self, terminal: Terminal, number: int) -> IoFunction | None:
        """The function a number gives this terminal, as the manual names it; None where it names none."""
        if number in terminal.special:
            return IoFunction(terminal.special[number], source=terminal.source)
        return self.functions.get(number)


@dataclass(frozen=True)
class IoMap:
    inputs: TerminalGroup | None = None
    outputs: TerminalGroup | None = None

    @property
    def groups(self) -> tuple[TerminalGroup, ...]:
        return tuple(g for g in (self.inputs, self.outputs) if g is not None)


def split_part(text: str) -> tuple[str, str | None]:
    """'Po407.X' -> ('Po407', 'X'); 'H03-02' -> ('H03-02', None)."""
    code, dot, part = text.partition(".")
    return (code, part) if dot else (text, None)
