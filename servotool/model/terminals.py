"""A drive's digital inputs and outputs as its manual documents them (profile section `io`).

Each group (inputs, outputs) names the monitor entry whose bits give each terminal's level, the entry (or field of
one) that assigns each terminal its function, and the manual's function-code table; a terminal without an
assignment parameter has its one function fixed. What a manual leaves open (a bit layout, a function table it does
not print) is said with `unverified`, as for entries, so that a function is never named where the manual does not.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from servotool.model.checker import Checker
from servotool.model.profile import Entry

DIRECTIONS = ("inputs", "outputs")
# What drives a simulated output (sim.terminals): the simulated drive's own state, nothing the manual does not name.
SIM_OUTPUT_STATES = ("ready", "servo_on", "rotating", "zero_speed", "in_position", "alarm", "brake_released")
FUNCTION_KEYS = {"name", "meaning", "source", "unverified", "sim"}
TERMINAL_KEYS = {"name", "bit", "function", "fixed", "logic", "special", "note", "source", "unverified"}
GROUP_KEYS = {"monitor", "terminals", "functions", "unlisted", "source", "unverified"}


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
        """'ALM (servo alarm)', or the name alone."""
        return f"{self.name} ({self.meaning})" if self.meaning and self.meaning != self.name else self.name


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


def part_value(entry: Entry, raw: int, part: str | None) -> int:
    """The value of CODE.PART in a raw value: a digit field (Po407.X), a named bit (Pn408.DI1), or the whole value."""
    if part is None:
        return raw
    upper = part.upper()
    if entry.format == "digits":
        names = [f.upper() for f in entry.fields]
        index = names.index(upper)
        return (raw >> (entry.field_width * index)) & ((1 << entry.field_width) - 1)
    bit = next(b for b, name in entry.bits.items() if name.upper() == upper)
    return raw >> bit & 1


def split_part(text: str) -> tuple[str, str | None]:
    """'Po407.X' -> ('Po407', 'X'); 'H03-02' -> ('H03-02', None)."""
    code, dot, part = text.partition(".")
    return (code, part) if dot else (text, None)


def parse_io(chk: Checker, raw: Any, entries: dict[str, Entry]) -> IoMap | None:
    """The profile's `io` section, every problem with its location; None where the profile has none."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("io", "expected a mapping {inputs, outputs}")
        return None
    chk.known_keys(raw, DIRECTIONS, "io")
    groups = {d: _group(chk, raw[d], f"io.{d}", d, entries) for d in DIRECTIONS if raw.get(d) is not None}
    return IoMap(groups.get("inputs"), groups.get("outputs"))


def _group(chk: Checker, raw: Any, loc: str, direction: str, entries: dict[str, Entry]) -> TerminalGroup | None:
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping {monitor, terminals, functions, source}")
        return None
    chk.known_keys(raw, GROUP_KEYS, loc)
    monitor = chk.need(raw, "monitor", loc, str)
    source = chk.need(raw, "source", loc, str)
    words = 1
    if monitor is not None:
        found = entries.get(monitor.upper())
        if found is None or not found.readable:
            chk.bad(f"{loc}.monitor", f"names no readable entry: {monitor!r}")
        else:
            monitor, words = found.code, found.words
    functions = {
        n: f
        for n, item in _int_keyed(chk, raw.get("functions"), f"{loc}.functions").items()
        if (f := _function(chk, item, f"{loc}.functions.{n}", direction)) is not None
    }
    terminals: list[Terminal] = []
    items = raw.get("terminals")
    if not isinstance(items, list) or not items:
        chk.bad(f"{loc}.terminals", "expected a non-empty list")
        items = []
    for i, item in enumerate(items):
        t = _terminal(chk, item, f"{loc}.terminals[{i}]", direction, entries, 16 * words)
        if t is not None:
            terminals.append(t)
    for seen_loc, key in (("name", lambda t: t.name.upper()), ("bit", lambda t: t.bit)):
        values = [key(t) for t in terminals]
        if len(set(values)) != len(values):
            chk.bad(f"{loc}.terminals", f"two terminals share a {seen_loc}")
    return TerminalGroup(
        direction=direction,
        monitor=monitor or "",
        terminals=tuple(terminals),
        functions=functions,
        source=source or "",
        unlisted=chk.opt(raw, "unlisted", loc, str, ""),
        unverified=chk.opt(raw, "unverified", loc, str, ""),
    )


def _int_keyed(chk: Checker, raw: Any, loc: str) -> dict[int, Any]:
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping of function number -> {name, meaning, source}")
        return {}
    out: dict[int, Any] = {}
    for key, value in raw.items():
        if not isinstance(key, int) or isinstance(key, bool) or key < 0:
            chk.bad(loc, f"key {key!r} is not a function number")
            continue
        out[key] = value
    return out


def _function(chk: Checker, raw: Any, loc: str, direction: str) -> IoFunction | None:
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping {name, meaning, source}")
        return None
    chk.known_keys(raw, FUNCTION_KEYS, loc)
    name = chk.need(raw, "name", loc, str)
    sim = chk.opt(raw, "sim", loc, str, "")
    if sim and (direction != "outputs" or sim not in SIM_OUTPUT_STATES):
        chk.bad(f"{loc}.sim", f"'{sim}' is not one of {', '.join(SIM_OUTPUT_STATES)} (outputs only)")
        sim = ""
    if name is None:
        return None
    return IoFunction(
        name=name,
        meaning=chk.opt(raw, "meaning", loc, str, ""),
        source=chk.opt(raw, "source", loc, str, ""),
        unverified=chk.opt(raw, "unverified", loc, str, ""),
        sim=sim,
    )


def _terminal(
    chk: Checker, raw: Any, loc: str, direction: str, entries: dict[str, Entry], bits: int
) -> Terminal | None:
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping {name, bit, function | fixed}")
        return None
    chk.known_keys(raw, TERMINAL_KEYS, loc)
    name = chk.need(raw, "name", loc, str)
    bit = chk.need(raw, "bit", loc, int)
    if name is None or bit is None:
        return None
    loc = f"{loc} ({name})"
    if not 0 <= bit < bits:
        chk.bad(f"{loc}.bit", f"{bit} is outside the monitor's {bits} bits")
    function = _reference(chk, raw, "function", loc, entries)
    logic = _reference(chk, raw, "logic", loc, entries)
    fixed = _function(chk, raw["fixed"], f"{loc}.fixed", direction) if raw.get("fixed") is not None else None
    if bool(function) == (fixed is not None):
        chk.bad(loc, "needs either 'function' (the entry assigning it) or 'fixed' (its one function)")
    special = {n: str(v) for n, v in _int_keyed(chk, raw.get("special"), f"{loc}.special").items()}
    return Terminal(
        name=name,
        bit=bit,
        function=function,
        fixed=fixed,
        logic=logic,
        special=special,
        note=chk.opt(raw, "note", loc, str, ""),
        source=chk.opt(raw, "source", loc, str, ""),
        unverified=chk.opt(raw, "unverified", loc, str, ""),
    )


def _reference(chk: Checker, raw: dict[str, Any], key: str, loc: str, entries: dict[str, Entry]) -> str:
    """CODE or CODE.PART naming a readable entry (and a digit field or bit name of it), as given; '' if absent."""
    text = chk.opt(raw, key, loc, str, "")
    if not text:
        return ""
    code, part = split_part(text)
    entry = entries.get(code.upper())
    if entry is None or not entry.readable:
        chk.bad(f"{loc}.{key}", f"names no readable entry: {text!r}")
        return ""
    parts = [f.upper() for f in entry.fields] if entry.format == "digits" else [b.upper() for b in entry.bits.values()]
    if part is not None and part.upper() not in parts:
        chk.bad(f"{loc}.{key}", f"{entry.code} has no field or bit named {part!r}")
        return ""
    return f"{entry.code}.{part}" if part is not None else entry.code
