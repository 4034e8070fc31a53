"""Profile schema validation: every problem of a YAML profile with its location (see profiles/SCHEMA.md)."""

from __future__ import annotations

import math
from typing import Any

from servotool.model.checker import Checker
from servotool.model.entry_schema import check_overlaps, parse_entry
from servotool.model.identity import parse_identity
from servotool.model.profile import (
    ALARM_KINDS,
    CONVENTIONS,
    PERSISTENCE,
    WORD_ORDERS,
    Alarm,
    DeadManRoute,
    Entry,
    Limits,
    LineSettings,
    Motor,
    Persistence,
    Profile,
    SetupItem,
)

TOP_KEYS = {
    "schema",
    "id",
    "model",
    "vendor",
    "version",
    "description",
    "source",
    "address_rule",
    "serial",
    "limits",
    "word_order",
    "persistence",
    "motor",
    "unverified_note",
    "groups",
    "roles",
    "entries",
    "alarms",
    "conventions",
    "motion_setup",
    "dead_man",
    "identity",
}
DEAD_MAN_ROUTES = ("drive_timeout", "segment", "none")
DEAD_MAN_KEYS = {
    "route",
    "reason",
    "source",
    "unverified",
    "if_host_dies",
    "start_value",
    "ramp_reference_rpm",
    "ramp_source",
}


SETUP_KEYS = {"code", "value", "reason", "source", "unverified"}


def parse_profile(data: Any, where: str) -> tuple[Profile | None, list[str]]:
    """Validate parsed YAML; return the profile (None if broken) and every problem found."""
    chk = Checker(where)
    if not isinstance(data, dict):
        chk.bad("top", "a profile must be a YAML mapping")
        return None, chk.problems
    chk.known_keys(data, TOP_KEYS, "top")
    if data.get("schema") != 1:
        chk.bad("schema", f"expected schema: 1, got {data.get('schema')!r}")
    pid = chk.need(data, "id", "top", str)
    texts = {
        k: chk.need(data, k, "top", str)
        for k in ("model", "vendor", "version", "description", "source", "address_rule")
    }
    word_order = chk.choice(data, "word_order", "top", WORD_ORDERS, "low_first")
    if "word_order" not in data:
        chk.bad("top", "missing required key 'word_order'")
    line, default_unit = _parse_serial(chk, data.get("serial"))
    limits = _parse_limits(chk, data.get("limits"))
    persistence = _parse_persistence(chk, data.get("persistence"))
    motor = _parse_motor(chk, data.get("motor"))
    groups = data.get("groups") or {}
    if not isinstance(groups, dict):
        chk.bad("groups", "expected a mapping of group id -> title")
        groups = {}
    entries, broken = _parse_entries(chk, data.get("entries"), word_order)
    codes = {e.code.upper() for e in entries}
    if groups:
        for e in entries:
            if e.group and e.group not in groups:
                chk.bad(f"entry {e.code}", f"group '{e.group}' is not declared in 'groups'")
    roles = _parse_roles(chk, data.get("roles"), codes, broken)
    if persistence.mode == "switchable" and persistence.switch_code.upper() not in codes:
        chk.bad("persistence.switch.code", f"names unknown entry {persistence.switch_code!r}")
    if persistence.mode == "ram" and "eeprom_save" not in roles and not persistence.note:
        chk.bad("persistence.note", "mode 'ram' without role 'eeprom_save' must say how the drive stores values")
    alarms = _parse_alarms(chk, data.get("alarms"))
    conventions = _parse_conventions(chk, data.get("conventions"))
    motion_setup = _parse_motion_setup(chk, data.get("motion_setup"), {e.code.upper(): e for e in entries}, broken)
    dead_man = _parse_dead_man(chk, data.get("dead_man"))
    identity = parse_identity(chk, data.get("identity"), {e.code.upper(): e for e in entries}, limits)
    if chk.problems or pid is None or any(v is None for v in texts.values()):
        return None, chk.problems
    profile = Profile(
        id=pid,
        model=texts["model"],
        vendor=texts["vendor"],
        version=texts["version"],
        description=texts["description"],
        source=texts["source"],
        address_rule=texts["address_rule"],
        line=line,
        default_unit=default_unit,
        limits=limits,
        word_order=word_order,
        persistence=persistence,
        motor=motor,
        entries=entries,
        roles={str(k): str(v) for k, v in roles.items()},
        groups={str(k): str(v) for k, v in groups.items()},
        alarms=alarms,
        conventions={str(k): str(v) for k, v in conventions.items()},
        motion_setup=motion_setup,
        unverified_note=str(data.get("unverified_note", "")),
        dead_man=dead_man,
        identity=identity,
    )
    return profile, []


def _parse_entries(chk: Checker, raw_entries: Any, word_order: str) -> tuple[list[Entry], set[str]]:
    """The entries that parse, and the codes of those present but broken (references to them are not
    'unknown')."""
    if not isinstance(raw_entries, list) or not raw_entries:
        chk.bad("entries", "expected a non-empty list")
        raw_entries = []
    parsed = [(i, e) for i, raw in enumerate(raw_entries) if (e := parse_entry(chk, raw, i, word_order))]
    check_overlaps(chk, parsed)
    entries = [e for _, e in parsed]
    codes = {e.code.upper() for e in entries}
    broken = {str(raw["code"]).upper() for raw in raw_entries if isinstance(raw, dict) and "code" in raw} - codes
    return entries, broken


def _parse_roles(chk: Checker, raw: Any, codes: set[str], broken: set[str]) -> dict[Any, Any]:
    roles = raw or {}
    if not isinstance(roles, dict):
        chk.bad("roles", "expected a mapping of role -> code")
        return {}
    for role, code in roles.items():
        if isinstance(code, str) and code.upper() in broken:
            chk.bad(f"roles.{role}", f"names broken entry {code!r} (see its own problem)")
        elif not isinstance(code, str) or code.upper() not in codes:
            chk.bad(f"roles.{role}", f"names unknown entry {code!r}")
    return roles


def _parse_conventions(chk: Checker, raw: Any) -> dict[Any, Any]:
    conventions = raw or {}
    if not isinstance(conventions, dict):
        chk.bad("conventions", "expected a mapping")
        return {}
    for key, value in conventions.items():
        if key not in CONVENTIONS or value not in CONVENTIONS[key]:
            chk.bad(f"conventions.{key}", f"unknown convention {key}: {value!r}")
    return conventions


def _parse_dead_man(chk: Checker, raw: Any) -> DeadManRoute | None:
    """dead_man: what stops host motion on this drive when the host dies (route, reason, source, unverified)."""
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("dead_man", "expected a mapping {route, reason, source, unverified, if_host_dies}")
        return None
    chk.known_keys(raw, DEAD_MAN_KEYS, "dead_man")
    route = chk.choice(raw, "route", "dead_man", DEAD_MAN_ROUTES, "none")
    keys = ("reason", "source", "unverified", "if_host_dies", "ramp_source")
    texts = {k: chk.opt(raw, k, "dead_man", str, "") for k in keys}
    if not texts["reason"] or not texts["source"]:
        chk.bad("dead_man", "needs a reason and a source (the manual lines it relies on)")
    start_value = chk.opt(raw, "start_value", "dead_man", int, 1)
    reference = raw.get("ramp_reference_rpm")
    if reference == "rated":
        reference = 0.0
    elif reference is not None and not (isinstance(reference, int | float) and reference > 0):
        chk.bad("dead_man.ramp_reference_rpm", "expected a speed in rpm > 0, or 'rated'")
        reference = None
    if reference is not None and not texts["ramp_source"]:
        chk.bad("dead_man", "ramp_reference_rpm needs a ramp_source (the manual lines, or why it is inferred)")
    return DeadManRoute(
        route=route,
        start_value=start_value,
        ramp_reference_rpm=float(reference) if reference is not None else None,
        **texts,
    )


def _parse_motion_setup(chk: Checker, raw: Any, entries: dict[str, Entry], broken: set[str]) -> list[SetupItem]:
    """motion_setup: known writable Pn codes, each value valid for its entry (parsed as `param set` would)."""
    from servotool.errors import ServoError
    from servotool.model.setup import requirement

    out: list[SetupItem] = []
    seen: set[str] = set()
    for loc, item in _mappings(chk, raw, "motion_setup", "{code, value, reason, source}"):
        chk.known_keys(item, SETUP_KEYS, loc)
        code = chk.need(item, "code", loc, str)
        value = chk.need(item, "value", loc, (str, int, float))
        reason = chk.need(item, "reason", loc, str)
        source = chk.need(item, "source", loc, str)
        unverified = chk.opt(item, "unverified", loc, str, "")
        if code is None or value is None or reason is None or source is None:
            continue
        loc = f"{loc} ({code})"
        entry = entries.get(code.upper())
        if entry is None:
            if code.upper() not in broken:
                chk.bad(f"{loc}.code", f"names unknown entry {code!r}")
            continue
        if entry.cls != "Pn" or not entry.writable:
            chk.bad(
                f"{loc}.code", f"{entry.code} is not a settable parameter (class {entry.cls}, access {entry.access})"
            )
            continue
        if entry.code.upper() in seen:
            chk.bad(f"{loc}.code", f"{entry.code} is listed twice")
        seen.add(entry.code.upper())
        text = str(value)
        try:
            requirement(entry, text)
        except ServoError as exc:
            chk.bad(f"{loc}.value", str(exc))
            continue
        out.append(SetupItem(entry.code, text, reason, source, unverified))
    return out


def _mappings(chk: Checker, raw: Any, name: str, shape: str = "") -> list[tuple[str, dict[str, Any]]]:
    """The items of an optional top-level list of mappings, with their locations; problems go to the checker."""
    if raw is None:
        return []
    if not isinstance(raw, list):
        chk.bad(name, "expected a list")
        return []
    items = []
    for i, item in enumerate(raw):
        if isinstance(item, dict):
            items.append((f"{name}[{i}]", item))
        else:
            chk.bad(f"{name}[{i}]", f"expected a mapping {shape}".rstrip())
    return items


ALARM_KEYS = {"code", "name", "clearable", "display", "source", "kind"}
SERIAL_KEYS = {"baud", "parity", "stopbits", "bytesize", "unit"}


def _parse_alarms(chk: Checker, raw: Any) -> list[Alarm]:
    out: list[Alarm] = []
    seen: set[int] = set()
    for loc, item in _mappings(chk, raw, "alarms"):
        chk.known_keys(item, ALARM_KEYS, loc)
        code = chk.need(item, "code", loc, int)
        name = chk.need(item, "name", loc, str)
        kind = chk.choice(item, "kind", loc, ALARM_KINDS, "other")
        if code is None or name is None:
            continue
        if code in seen:
            chk.bad(loc, f"duplicate alarm code {code}")
        seen.add(code)
        out.append(
            Alarm(
                code=code,
                display=str(item.get("display", code)),
                name=name,
                clearable=bool(item.get("clearable", True)),
                kind=kind,
                source=str(item.get("source", "")),
            )
        )
    return out


def _parse_serial(chk: Checker, raw: Any) -> tuple[LineSettings, int]:
    if not isinstance(raw, dict):
        chk.bad("serial", "missing or not a mapping")
        return LineSettings(), 1
    chk.known_keys(raw, SERIAL_KEYS, "serial")
    s = LineSettings(
        baud=chk.opt(raw, "baud", "serial", int, 9600),
        parity=chk.choice(raw, "parity", "serial", ("N", "E", "O"), "N"),
        stopbits=chk.opt(raw, "stopbits", "serial", int, 1),
        bytesize=chk.opt(raw, "bytesize", "serial", int, 8),
    )
    unit = chk.opt(raw, "unit", "serial", int, 1)
    if s.baud <= 0:
        chk.bad("serial.baud", "must be positive")
    if s.stopbits not in (1, 2):
        chk.bad("serial.stopbits", "must be 1 or 2")
    if s.bytesize not in (7, 8):
        chk.bad("serial.bytesize", "must be 7 or 8")
    if not 0 <= unit <= 247:
        chk.bad("serial.unit", "must be 0..247")
    return s, unit


def _parse_limits(chk: Checker, raw: Any) -> Limits:
    if not isinstance(raw, dict):
        chk.bad("limits", "missing or not a mapping")
        return Limits()
    lim = Limits(
        max_read=chk.opt(raw, "max_read", "limits", int, 125),
        max_write=chk.opt(raw, "max_write", "limits", int, 123),
        write_multiple=chk.opt(raw, "write_multiple", "limits", bool, True),
    )
    if not 1 <= lim.max_read <= 125:
        chk.bad("limits.max_read", "must be 1..125")
    if not 1 <= lim.max_write <= 123:
        chk.bad("limits.max_write", "must be 1..123")
    return lim


def _parse_persistence(chk: Checker, raw: Any) -> Persistence:
    if not isinstance(raw, dict):
        chk.bad("persistence", "missing or not a mapping")
        return Persistence()
    mode = chk.choice(raw, "mode", "persistence", PERSISTENCE, "immediate")
    switch = raw.get("switch") or {}
    if mode == "switchable" and not isinstance(switch, dict):
        chk.bad("persistence.switch", "expected a mapping {code, eeprom, ram}")
        switch = {}
    if mode == "switchable" and "code" not in switch:
        chk.bad("persistence.switch", "mode 'switchable' needs switch.code")
    return Persistence(
        mode=mode,
        switch_code=str(switch.get("code", "")),
        switch_eeprom=int(switch.get("eeprom", 0)),
        switch_ram=int(switch.get("ram", 1)),
        switch_digit=str(switch.get("digit", "") or ""),
        write_limit=chk.opt(raw, "write_limit", "persistence", int, None),
        note=str(raw.get("note", "") or ""),
    )


def _parse_motor(chk: Checker, raw: Any) -> Motor | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("motor", "expected a mapping")
        return None
    vals = {}
    for key in ("rated_torque_nm", "rated_speed_rpm", "max_speed_rpm", "rotor_inertia_kgcm2"):
        v = chk.need(raw, key, "motor", (int, float))
        if v is not None and not (math.isfinite(v) and 1e-9 <= v <= 1e9):
            chk.bad(f"motor.{key}", "must be a finite number > 0 (1e-9..1e9)")
            v = None
        vals[key] = float(v or 1.0)
    cpr = chk.need(raw, "counts_per_rev", "motor", int) or 131072
    return Motor(counts_per_rev=cpr, source=str(raw.get("source", "") or ""), **vals)
