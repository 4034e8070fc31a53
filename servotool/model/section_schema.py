"""Parsing the profile sections beyond the register map: the drive's inputs and outputs (`io`, model.terminals),
its alarm causes and log (`alarm_causes`, `alarm_log`, model.alarm_notes), and `unverified_values` (the entries
whose value's scale or meaning the manual leaves open: wherever such a value is shown, it is marked with the
reason). Every problem with its location, as for the rest of a profile."""

from __future__ import annotations

from typing import Any

from servotool.model.alarm_notes import (
    CONTEXT_KEYS,
    AlarmCauses,
    AlarmLog,
    AlarmNote,
    CauseRemedy,
    RecordSelector,
)
from servotool.model.checker import Checker
from servotool.model.profile import Entry
from servotool.model.terminals import (
    DIRECTIONS,
    SIM_OUTPUT_STATES,
    IoFunction,
    IoMap,
    Terminal,
    TerminalGroup,
    split_part,
)

FUNCTION_KEYS = {"name", "meaning", "source", "unverified", "sim"}
TERMINAL_KEYS = {"name", "bit", "function", "fixed", "logic", "special", "note", "source", "unverified"}
GROUP_KEYS = {"monitor", "terminals", "functions", "unlisted", "source", "unverified"}
CAUSES_KEYS = {"source", "none", "items"}
ITEM_KEYS = {"codes", "causes", "source", "unverified"}
LOG_KEYS = {"context", "select", "excludes_current", "source", "unverified"}
SELECT_KEYS = {"code", "current", "past"}


class Known:
    """The entries a section may name (by upper-case code), and those present but broken: a reference to a broken
    entry is not blamed, since the entry's own problem says what to fix."""

    def __init__(self, entries: dict[str, Entry], broken: set[str]) -> None:
        self.entries, self.broken = entries, broken

    def get(self, code: str) -> Entry | None:
        return self.entries.get(code.upper())

    def blame(self, chk: Checker, loc: str, code: str, problem: str) -> None:
        if code.upper() not in self.broken:
            chk.bad(loc, problem)


def parse_io(chk: Checker, raw: Any, entries: Known) -> IoMap | None:
    """The profile's `io` section, every problem with its location; None where the profile has none."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("io", "expected a mapping {inputs, outputs}")
        return None
    chk.known_keys(raw, DIRECTIONS, "io")
    groups = {d: _group(chk, raw[d], f"io.{d}", d, entries) for d in DIRECTIONS if d in raw}
    return IoMap(groups.get("inputs"), groups.get("outputs"))


def _group(chk: Checker, raw: Any, loc: str, direction: str, entries: Known) -> TerminalGroup | None:
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
            entries.blame(chk, f"{loc}.monitor", monitor, f"names no readable entry: {monitor!r}")
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


def _terminal(chk: Checker, raw: Any, loc: str, direction: str, entries: Known, bits: int) -> Terminal | None:
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
    if ("function" in raw) == ("fixed" in raw):  # as given: a broken one has said what is wrong with it
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


def _reference(chk: Checker, raw: dict[str, Any], key: str, loc: str, entries: Known) -> str:
    """CODE or CODE.PART naming a readable entry (and a digit field or bit name of it), as given; '' if absent."""
    text = chk.opt(raw, key, loc, str, "")
    if not text:
        return ""
    code, part = split_part(text)
    entry = entries.get(code.upper())
    if entry is None or not entry.readable:
        entries.blame(chk, f"{loc}.{key}", code, f"names no readable entry: {text!r}")
        return ""
    parts = [f.upper() for f in entry.fields] if entry.format == "digits" else [b.upper() for b in entry.bits.values()]
    if part is not None and part.upper() not in parts:
        chk.bad(f"{loc}.{key}", f"{entry.code} has no field or bit named {part!r}")
        return ""
    return f"{entry.code}.{part}" if part is not None else entry.code


def parse_alarm_causes(chk: Checker, raw: Any, alarm_codes: set[int] | None) -> AlarmCauses | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("alarm_causes", "expected a mapping {source, none, items}")
        return None
    chk.known_keys(raw, CAUSES_KEYS, "alarm_causes")
    source = chk.need(raw, "source", "alarm_causes", str)
    none = chk.need(raw, "none", "alarm_causes", str)
    items = raw.get("items") or []
    if not isinstance(items, list):
        chk.bad("alarm_causes.items", "expected a list")
        items = []
    notes: list[AlarmNote] = []
    seen: set[int] = set()
    for i, item in enumerate(items):
        loc = f"alarm_causes.items[{i}]"
        if not isinstance(item, dict):
            chk.bad(loc, "expected a mapping {codes, causes, source}")
            continue
        chk.known_keys(item, ITEM_KEYS, loc)
        codes = item.get("codes")
        if not isinstance(codes, list) or not codes or not all(isinstance(c, int) for c in codes):
            chk.bad(f"{loc}.codes", "expected a non-empty list of alarm codes")
            continue
        for c in codes:
            if alarm_codes is not None and c not in alarm_codes:
                chk.bad(f"{loc}.codes", f"{c} is not in the profile's alarms")
            if c in seen:
                chk.bad(f"{loc}.codes", f"alarm {c} has causes twice")
            seen.add(c)
        causes = _causes(chk, item.get("causes"), f"{loc}.causes")
        item_source = chk.need(item, "source", loc, str)
        if causes and item_source:
            notes.append(AlarmNote(tuple(codes), causes, item_source, chk.opt(item, "unverified", loc, str, "")))
    if source is None or none is None:
        return None
    return AlarmCauses(source, none, tuple(notes))


def _causes(chk: Checker, raw: Any, loc: str) -> tuple[CauseRemedy, ...]:
    if not isinstance(raw, list) or not raw:
        chk.bad(loc, "expected a non-empty list of {cause, remedy}")
        return ()
    out: list[CauseRemedy] = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict):
            chk.bad(f"{loc}[{i}]", "expected a mapping {cause, remedy}")
            continue
        chk.known_keys(item, {"cause", "remedy"}, f"{loc}[{i}]")
        cause = chk.need(item, "cause", f"{loc}[{i}]", str)
        remedy = chk.need(item, "remedy", f"{loc}[{i}]", str)
        if cause is not None and remedy is not None:
            out.append(CauseRemedy(cause, remedy))
    return tuple(out)


def parse_alarm_log(chk: Checker, raw: Any, entries: Known) -> AlarmLog | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("alarm_log", "expected a mapping {context, select, source}")
        return None
    chk.known_keys(raw, LOG_KEYS, "alarm_log")
    source = chk.need(raw, "source", "alarm_log", str)
    context: dict[str, dict[str, str]] = {}
    given = raw.get("context") or {}
    if not isinstance(given, dict):
        chk.bad("alarm_log.context", "expected a mapping of record code -> {meaning: code}")
        given = {}
    for record, values in given.items():
        loc = f"alarm_log.context.{record}"
        entry = entries.get(str(record).upper())
        if entry is None or not entry.readable:
            entries.blame(chk, loc, str(record), f"names no readable entry: {record!r}")
            continue
        if not isinstance(values, dict):
            chk.bad(loc, f"expected a mapping of {', '.join(CONTEXT_KEYS)} -> code")
            continue
        chk.known_keys(values, CONTEXT_KEYS, loc)
        found = {k: entries.get(str(v).upper()) for k, v in values.items() if k in CONTEXT_KEYS}
        for k, e in found.items():
            if e is None or not e.readable:
                entries.blame(chk, f"{loc}.{k}", str(values[k]), f"names no readable entry: {values[k]!r}")
        context[entry.code.upper()] = {k: e.code for k, e in found.items() if e is not None and e.readable}
    select = _selector(chk, raw["select"], entries) if "select" in raw else None
    if source is None:
        return None
    return AlarmLog(
        source=source,
        context=context,
        select=select,
        excludes_current=chk.opt(raw, "excludes_current", "alarm_log", bool, False),
        unverified=chk.opt(raw, "unverified", "alarm_log", str, ""),
    )


def _selector(chk: Checker, raw: Any, entries: Known) -> RecordSelector | None:
    if not isinstance(raw, dict):
        chk.bad("alarm_log.select", "expected a mapping {code, current, past}")
        return None
    chk.known_keys(raw, SELECT_KEYS, "alarm_log.select")
    code = chk.need(raw, "code", "alarm_log.select", str)
    current = chk.need(raw, "current", "alarm_log.select", int)
    past = chk.need(raw, "past", "alarm_log.select", int)
    if code is None or current is None or past is None:
        return None
    entry = entries.get(code.upper())
    if entry is None or not (entry.readable and entry.writable):
        entries.blame(chk, "alarm_log.select.code", code, f"names no readable and writable entry: {code!r}")
        return None
    if past < 1 or not entry.min <= current <= entry.max or not entry.min <= past <= entry.max:
        chk.bad("alarm_log.select", f"current and 1..past must lie in {entry.code}'s range {entry.min}..{entry.max}")
        return None
    return RecordSelector(entry.code, current, past)


def parse_unverified_values(chk: Checker, raw: Any, entries: Known) -> dict[str, str]:
    """Entry code (upper case) -> why its value's scale or meaning is unverified. Each item is a code (the entry's
    own `unverified` text says why) or a one-key mapping {code: reason}."""
    if raw is None:
        return {}
    if not isinstance(raw, list):
        chk.bad("unverified_values", "expected a list of entry codes or {code: reason}")
        return {}
    out: dict[str, str] = {}
    for i, item in enumerate(raw):
        loc = f"unverified_values[{i}]"
        if isinstance(item, dict) and len(item) == 1:
            code, reason = next(iter(item.items()))
        elif isinstance(item, str):
            code, reason = item, None
        else:
            chk.bad(loc, "expected an entry code or {code: reason}")
            continue
        entry = entries.get(str(code).upper())
        if entry is None:
            entries.blame(chk, loc, str(code), f"names unknown entry {code!r}")
            continue
        reason = entry.unverified if reason is None else reason
        if not isinstance(reason, str) or not reason.strip():
            chk.bad(loc, f"{entry.code}: give the reason (the entry has no 'unverified' text to stand for it)")
        elif entry.code.upper() in out:
            chk.bad(loc, f"{entry.code} is listed twice")
        else:
            out[entry.code.upper()] = " ".join(reason.split())
    return out
