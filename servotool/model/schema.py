"""Profile schema validation: every problem of a YAML profile with its location (see profiles/SCHEMA.md)."""

from __future__ import annotations

import math
import re
from typing import Any

from servotool.model.checker import Checker, shown
from servotool.model.entry_schema import check_overlaps, parse_entry
from servotool.model.identity import parse_identity
from servotool.model.profile import (
    ALARM_KINDS,
    CONVENTIONS,
    FORCED_MONITOR,
    PERSISTENCE,
    WORD_ORDERS,
    Alarm,
    DeadManRoute,
    Entry,
    ForcedInputs,
    Limits,
    LineBoost,
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
    "forced_inputs",
    "identity",
    "io",
    "alarm_causes",
    "alarm_log",
    "unverified_values",
}
ID_PATTERN = re.compile(r"[a-z0-9][a-z0-9_-]*")
ROLE_PATTERN = re.compile(r"[a-z][a-z0-9_]*")
GROUP_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
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
FORCED_KEYS = {"switch", "levels", "monitor", "monitor_shows", "source", "unverified"}


SETUP_KEYS = {"code", "value", "reason", "source", "unverified"}
ALARM_KEYS = {"code", "name", "clearable", "display", "source", "kind"}
SERIAL_KEYS = {"baud", "parity", "stopbits", "bytesize", "unit", "boost"}
LIMITS_KEYS = {"max_read", "max_write", "write_multiple"}
PERSISTENCE_KEYS = {"mode", "switch", "write_limit", "note"}
SWITCH_KEYS = {"code", "eeprom", "ram", "digit"}
MOTOR_KEYS = {"rated_torque_nm", "rated_speed_rpm", "max_speed_rpm", "rotor_inertia_kgcm2", "counts_per_rev", "source"}


def parse_profile(data: Any, where: str) -> tuple[Profile | None, list[str]]:
    """Validate parsed YAML; return the profile (None if broken) and every problem found. A value that breaks
    one field is one problem: what refers to a broken entry is not blamed as well."""
    chk = Checker(where)
    if not isinstance(data, dict):
        chk.bad("", "a profile must be a YAML mapping")
        return None, chk.problems
    chk.known_keys(data, TOP_KEYS, "")
    if "schema" not in data:
        chk.bad("", "missing required key 'schema'")
    elif data["schema"] != 1 or isinstance(data["schema"], bool):
        chk.bad("schema", f"expected 1, got {shown(data['schema'])}")
    pid = _profile_id(chk, data)
    texts = {
        k: chk.need(data, k, "", str) for k in ("model", "vendor", "version", "description", "source", "address_rule")
    }
    word_order = chk.choice(data, "word_order", "", WORD_ORDERS, "low_first", required=True)
    line, default_unit = _parse_serial(chk, _section(chk, data, "serial"))
    limits = _parse_limits(chk, _section(chk, data, "limits"))
    persistence = _parse_persistence(chk, _section(chk, data, "persistence"))
    motor = _parse_motor(chk, _section(chk, data, "motor", required=False))
    unverified_note = chk.opt(data, "unverified_note", "", str, "")
    groups = _names(chk, data, "groups", GROUP_PATTERN, "group id -> title")
    alarms = _parse_alarms(chk, data)
    conventions = _parse_conventions(chk, data)
    dead_man = _parse_dead_man(chk, _section(chk, data, "dead_man", required=False))
    raw_entries = data.get("entries")
    if not isinstance(raw_entries, list) or not raw_entries:  # nothing that names an entry can be checked
        chk.bad("entries", f"expected a non-empty list, got {shown(raw_entries)}")
        return None, chk.problems
    entries, broken = _parse_entries(chk, raw_entries, word_order)
    by_code = {e.code.upper(): e for _, e in entries}
    if isinstance(data.get("groups"), dict):  # a broken 'groups' is one problem, not also each entry's
        declared = set(data["groups"])
        for i, e in entries:
            if e.group and e.group not in declared:
                chk.bad(f"entries[{i}] ({e.code}).group", f"'{e.group}' is not declared in 'groups'")
    roles = _parse_roles(chk, data, set(by_code), broken)
    _check_switch(chk, persistence, by_code, broken)
    if persistence.mode == "ram" and "eeprom_save" not in roles and not persistence.note:
        chk.bad("persistence.note", "mode 'ram' without role 'eeprom_save' must say how the drive stores values")
    motion_setup = _parse_motion_setup(chk, data, by_code, broken)
    forced = _parse_forced_inputs(chk, _section(chk, data, "forced_inputs", required=False), by_code, broken)
    identity = parse_identity(chk, data.get("identity"), by_code, limits, broken) if "identity" in data else None
    # with an alarm broken, which codes the alarm causes may name is not known: its own problem says what to fix
    listed = data.get("alarms", [])
    alarm_codes = {a.code for a in alarms} if isinstance(listed, list) and len(alarms) == len(listed) else None
    extras = _parse_extras(chk, data, by_code, broken, alarm_codes)
    serial = data.get("serial") if isinstance(data.get("serial"), dict) else {}
    # a broken or missing persistence section is no ground to refuse a boost on: its own problem says what to fix
    stored = persistence if isinstance(data.get("persistence"), dict) and _clean_section(chk, "persistence") else None
    boost = _parse_boost(chk, serial["boost"], by_code, broken, line, stored) if "boost" in serial else LineBoost()
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
        entries=[e for _, e in entries],
        roles=roles,
        groups=groups,
        alarms=alarms,
        conventions=conventions,
        motion_setup=motion_setup,
        unverified_note=unverified_note,
        dead_man=dead_man,
        forced_inputs=forced,
        identity=identity,
        **extras,
        boost=boost,
    )
    return profile, []


def _profile_id(chk: Checker, data: dict[str, Any]) -> str | None:
    pid = chk.need(data, "id", "", str)
    if pid is not None and not ID_PATTERN.fullmatch(pid):
        chk.bad("id", f"{shown(pid)} is not a lower-case id (letters, digits, '-' and '_')")
        return None
    return pid


def _clean_section(chk: Checker, key: str) -> bool:
    """Whether no problem was found so far in a top-level section (what another check may rely on)."""
    return not any(p.startswith(f"{chk.where}: {key}") for p in chk.problems)


def _section(
    chk: Checker, data: dict[str, Any], key: str, *, required: bool = True, loc: str = ""
) -> dict[str, Any] | None:
    """A mapping under the top level (or at loc); None (after reporting it, when it is required or malformed)
    otherwise."""
    if key not in data:
        if required:
            chk.bad(loc.rpartition(".")[0], f"missing required key '{key}'")
        return None
    value = data[key]
    if not isinstance(value, dict):
        chk.bad(loc or key, f"expected a mapping, got {shown(value)}")
        return None
    return value


def _names(chk: Checker, data: dict[str, Any], key: str, pattern: re.Pattern[str], shape: str) -> dict[str, str]:
    """An optional top-level mapping of names to texts (groups: id -> title; roles: role -> code)."""
    raw = _section(chk, data, key, required=False) or {}
    out: dict[str, str] = {}
    for name, text in raw.items():
        if not isinstance(name, str) or not pattern.fullmatch(name):
            chk.bad(key, f"{shown(name)} is not a name ({shape}; {pattern.pattern})")
        elif not isinstance(text, str) or not text.strip():
            chk.bad(f"{key}.{name}", f"expected a string ({shape}), got {shown(text)}")
        else:
            out[name] = text
    return out


def _parse_extras(
    chk: Checker, data: dict[str, Any], by_code: dict[str, Entry], broken: set[str], alarm_codes: set[int] | None
) -> dict[str, Any]:
    """The sections beyond the register map: inputs and outputs, alarm causes and log, unverified values."""
    from servotool.model.section_schema import (
        Known,
        parse_alarm_causes,
        parse_alarm_log,
        parse_io,
        parse_unverified_values,
    )

    entries = Known(by_code, broken)
    for key in ("io", "alarm_causes", "alarm_log", "unverified_values"):
        if key in data and data[key] is None:  # given empty: not the same as left out
            chk.bad(key, f"expected {'a list' if key == 'unverified_values' else 'a mapping'}, got {shown(None)}")
    return {
        "io": parse_io(chk, data.get("io"), entries),
        "alarm_causes": parse_alarm_causes(chk, data.get("alarm_causes"), alarm_codes),
        "alarm_log": parse_alarm_log(chk, data.get("alarm_log"), entries),
        "unverified_values": parse_unverified_values(chk, data.get("unverified_values"), entries),
    }


def _parse_entries(chk: Checker, raw_entries: list[Any], word_order: str) -> tuple[list[tuple[int, Entry]], set[str]]:
    """The entries that parse (with their position in the file), and the codes of those present but broken
    (references to them are not blamed: the entry's own problem says what to fix)."""
    parsed = [(i, e) for i, raw in enumerate(raw_entries) if (e := parse_entry(chk, raw, i, word_order))]
    check_overlaps(chk, parsed)
    codes = {e.code.upper() for _, e in parsed}
    broken = {str(raw["code"]).upper() for raw in raw_entries if isinstance(raw, dict) and "code" in raw} - codes
    return parsed, broken


def _parse_roles(chk: Checker, data: dict[str, Any], codes: set[str], broken: set[str]) -> dict[str, str]:
    roles = _names(chk, data, "roles", ROLE_PATTERN, "role -> entry code")
    for role, code in roles.items():
        if code.upper() not in codes and code.upper() not in broken:
            chk.bad(f"roles.{role}", f"names unknown entry {shown(code)}")
    return roles


def _check_switch(chk: Checker, persistence: Persistence, entries: dict[str, Entry], broken: set[str]) -> None:
    """The RAM/EEPROM switch names a settable entry (and one of its fields, with `digit`) whose range admits
    both values."""
    if persistence.mode == "switchable" and persistence.switch_code:
        values = {"eeprom": persistence.switch_eeprom, "ram": persistence.switch_ram}
        code, digit = persistence.switch_code, persistence.switch_digit
        _switch_entry(chk, "persistence.switch", code, digit, values, entries, broken)


def _switch_entry(
    chk: Checker, loc: str, code: str, digit: str, values: dict[str, int], entries: dict[str, Entry], broken: set[str]
) -> None:
    """A switch (the EEPROM switch, the input forcing switch) names a settable entry, and with `digit` one of its
    fields, whose range admits each of its values."""
    if code.upper() in broken:
        return
    entry = entries.get(code.upper())
    if entry is None:
        chk.bad(f"{loc}.code", f"names unknown entry {shown(code)}")
        return
    if entry.cls != "Pn" or not entry.writable:
        chk.bad(f"{loc}.code", f"{entry.code} is not a settable parameter")
        return
    if digit and digit.upper() not in {f.upper() for f in entry.fields}:
        chk.bad(f"{loc}.digit", f"{shown(digit)} is not a field of {entry.code} ({entry.fields or 'none'})")
        return
    limit = 99 if entry.field_width == 8 else 15
    lo, hi = entry.field_ranges.get(digit.upper(), (0, limit)) if digit else (entry.min, entry.max)
    for state, value in values.items():
        if not lo <= value <= hi:
            chk.bad(f"{loc}.{state}", f"{value} is outside {entry.code}'s range {lo}..{hi}")


def _parse_conventions(chk: Checker, data: dict[str, Any]) -> dict[str, str]:
    conventions = _section(chk, data, "conventions", required=False) or {}
    out: dict[str, str] = {}
    for key, value in conventions.items():
        if key not in CONVENTIONS or value not in CONVENTIONS[key]:
            chk.bad(f"conventions.{key}", f"unknown convention {key}: {shown(value)}")
        else:
            out[key] = value
    return out


def _parse_dead_man(chk: Checker, raw: dict[str, Any] | None) -> DeadManRoute | None:
    """dead_man: what stops host motion on this drive when the host dies (route, reason, source, unverified)."""
    if raw is None:
        return None
    chk.known_keys(raw, DEAD_MAN_KEYS, "dead_man")
    route = chk.choice(raw, "route", "dead_man", DEAD_MAN_ROUTES, "none", required=True)
    texts = {k: chk.need(raw, k, "dead_man", str) or "" for k in ("reason", "source")}
    texts |= {k: chk.opt(raw, k, "dead_man", str, "") for k in ("unverified", "if_host_dies", "ramp_source")}
    start_value = chk.whole(raw, "start_value", "dead_man", 1, 0xFFFF, 1)
    reference = _ramp_reference(chk, raw)
    if reference is not None and "ramp_source" not in raw:
        chk.bad(
            "dead_man", "missing key 'ramp_source': ramp_reference_rpm needs the manual lines, or why it is inferred"
        )
    return DeadManRoute(route=route, start_value=start_value, ramp_reference_rpm=reference, **texts)


def _ramp_reference(chk: Checker, raw: dict[str, Any]) -> float | None:
    """dead_man.ramp_reference_rpm: a speed in rpm > 0, or 'rated' (the motor's rated speed, read as 0.0); None when
    absent or broken (after reporting it)."""
    if "ramp_reference_rpm" not in raw:
        return None
    loc = "dead_man.ramp_reference_rpm"
    value = raw["ramp_reference_rpm"]
    if value == "rated":
        return 0.0
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        chk.bad(loc, f"expected a speed in rpm > 0 or 'rated', got {shown(value)}")
        return None
    return float(value)


def _parse_forced_inputs(
    chk: Checker, raw: dict[str, Any] | None, entries: dict[str, Entry], broken: set[str]
) -> ForcedInputs | None:
    """forced_inputs: the switch that forces the inputs (a settable entry or one of its fields, with its forced and
    released values), the forced levels' entry, the input monitor and what it shows while forcing is on."""
    if raw is None:
        return None
    chk.known_keys(raw, FORCED_KEYS, "forced_inputs")
    switch = _section(chk, raw, "switch", loc="forced_inputs.switch")
    levels = chk.need(raw, "levels", "forced_inputs", str)
    monitor = chk.need(raw, "monitor", "forced_inputs", str)
    source = chk.need(raw, "source", "forced_inputs", str)
    shows = chk.choice(raw, "monitor_shows", "forced_inputs", FORCED_MONITOR, "forced")
    unverified = chk.opt(raw, "unverified", "forced_inputs", str, "")
    for what, code in (("levels", levels), ("monitor", monitor)):
        if code is not None and code.upper() not in entries and code.upper() not in broken:
            chk.bad(f"forced_inputs.{what}", f"names unknown entry {shown(code)}")
    if switch is None:
        return None
    loc = "forced_inputs.switch"
    chk.known_keys(switch, {"code", "digit", "forced", "released"}, loc)
    code = chk.need(switch, "code", loc, str)
    digit = chk.opt(switch, "digit", loc, str, "")
    on = chk.whole(switch, "forced", loc, 0, 0xFFFF, 1)
    off = chk.whole(switch, "released", loc, 0, 0xFFFF, 0)
    if on == off and "forced" in switch and "released" in switch:
        chk.bad(f"{loc}.released", f"{off} is also the forced value: the two must differ")
    if code is None or levels is None or monitor is None or source is None:
        return None
    _switch_entry(chk, loc, code, digit, {"forced": on, "released": off}, entries, broken)
    return ForcedInputs(
        switch_code=code,
        levels_code=levels,
        monitor_code=monitor,
        source=source,
        digit=digit,
        on=on,
        off=off,
        monitor_shows=shows,
        unverified=unverified,
    )


def _parse_motion_setup(
    chk: Checker, data: dict[str, Any], entries: dict[str, Entry], broken: set[str]
) -> list[SetupItem]:
    """motion_setup: known writable Pn codes, each value valid for its entry (parsed as `param set` would)."""
    from servotool.errors import ServoError
    from servotool.model.setup import requirement

    out: list[SetupItem] = []
    seen: set[str] = set()
    for loc, item in _mappings(chk, data, "motion_setup", "{code, value, reason, source}"):
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
                chk.bad(f"{loc}.code", f"names unknown entry {shown(code)}")
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


def _mappings(chk: Checker, data: dict[str, Any], name: str, shape: str = "") -> list[tuple[str, dict[str, Any]]]:
    """The items of an optional top-level list of mappings, with their locations; problems go to the checker."""
    if name not in data:
        return []
    raw = data[name]
    if not isinstance(raw, list):
        chk.bad(name, f"expected a list, got {shown(raw)}")
        return []
    items = []
    for i, item in enumerate(raw):
        if isinstance(item, dict):
            items.append((f"{name}[{i}]", item))
        else:
            chk.bad(f"{name}[{i}]", f"expected a mapping {shape}, got {shown(item)}")
    return items


BOOST_KEYS = {"code", "rates", "to", "source", "unverified", "none"}


def _parse_alarms(chk: Checker, data: dict[str, Any]) -> list[Alarm]:
    out: list[Alarm] = []
    seen: dict[int, str] = {}
    for loc, item in _mappings(chk, data, "alarms", "{code, name, display, clearable, kind, source}"):
        chk.known_keys(item, ALARM_KEYS, loc)
        before = len(chk.problems)
        code = chk.whole(item, "code", loc, 0, 0xFFFFFFFF, 0, required=True)
        alarm = Alarm(
            code=code,
            display=chk.opt(item, "display", loc, str, str(code)),
            name=chk.need(item, "name", loc, str) or "",
            clearable=chk.opt(item, "clearable", loc, bool, True),
            kind=chk.choice(item, "kind", loc, ALARM_KINDS, "other"),
            source=chk.opt(item, "source", loc, str, ""),
        )
        if len(chk.problems) > before:
            continue
        if code in seen:
            chk.bad(f"{loc}.code", f"duplicate alarm code {code} (also {seen[code]})")
            continue
        seen[code] = loc
        out.append(alarm)
    return out


def _parse_serial(chk: Checker, raw: dict[str, Any] | None) -> tuple[LineSettings, int]:
    """The manual's factory line settings and slave address: each one required, since a default silently taken
    for the manual's value is a line that never answers."""
    if raw is None:
        return LineSettings(), 1
    chk.known_keys(raw, SERIAL_KEYS, "serial")
    line = LineSettings(
        baud=chk.whole(raw, "baud", "serial", 300, 10_000_000, 9600, required=True),
        parity=chk.choice(raw, "parity", "serial", ("N", "E", "O"), "N", required=True),
        stopbits=chk.whole(raw, "stopbits", "serial", 1, 2, 1, required=True),
        bytesize=chk.whole(raw, "bytesize", "serial", 7, 8, 8, required=True),
    )
    if raw.get("unit") == 0 and not isinstance(raw.get("unit"), bool):
        chk.bad("serial.unit", "0 is the broadcast address, which no drive answers: a drive's address is 1..247")
        return line, 1
    return line, chk.whole(raw, "unit", "serial", 1, 247, 1, required=True)


def _parse_boost(
    chk: Checker,
    raw: Any,
    entries: dict[str, Entry],
    broken: set[str],
    line: LineSettings,
    persistence: Persistence | None,
) -> LineBoost:
    """serial.boost: {code, rates: {raw: baud}, to, source, unverified} where the drive documents a baud entry
    that takes effect at once, or {none: why} where it does not. The factory line must be one of the codes, the
    entry immediate and writable, and the drive able to keep the change out of EEPROM (a power cycle must bring
    back the factory line)."""
    loc = "serial.boost"
    if not isinstance(raw, dict):
        chk.bad(loc, f"expected a mapping, got {shown(raw)}")
        return LineBoost()
    chk.known_keys(raw, BOOST_KEYS, loc)
    texts = {k: chk.opt(raw, k, loc, str, "") for k in ("unverified", "none")}
    texts["source"] = chk.need(raw, "source", loc, str) or ""
    if texts["none"]:
        if set(raw) - {"none", "source", "unverified"}:
            chk.bad(loc, "'none' (no boost, and why) goes without code, rates and to")
        return LineBoost(**texts)
    code, to = chk.need(raw, "code", loc, str), chk.need(raw, "to", loc, int)
    rates: dict[int, int] = {}
    given = chk.need(raw, "rates", loc, dict) or {}
    for key, baud in given.items():
        if isinstance(key, bool) or not isinstance(key, int) or isinstance(baud, bool) or not isinstance(baud, int):
            chk.bad(f"{loc}.rates", f"expected raw code: baud (integers), got {key!r}: {baud!r}")
        elif baud <= 0:
            chk.bad(f"{loc}.rates", f"baud {baud} must be positive")
        else:
            rates[key] = baud
    entry = entries.get(str(code).upper()) if code else None
    if code and entry is None and str(code).upper() not in broken:
        chk.bad(f"{loc}.code", f"names unknown entry {code!r}")
    if entry is not None:
        if entry.effect != "immediate" or not entry.writable:
            chk.bad(f"{loc}.code", f"{entry.code} must be a writable entry that takes effect immediately")
        if any(not entry.min <= r <= entry.max for r in rates):
            chk.bad(f"{loc}.rates", f"a code outside {entry.code}'s range {entry.min}..{entry.max}")
    if rates and line.baud not in rates.values():
        chk.bad(f"{loc}.rates", f"no code for the factory line's {line.baud} baud")
    elif to is not None and rates and to not in rates.values():  # (rates already blamed: not `to` as well)
        chk.bad(f"{loc}.to", f"{to} baud has no code in rates")
    if persistence is not None and persistence.mode == "immediate":
        chk.bad(loc, "a drive that stores every write would keep the raised line after a power cycle")
    if code is None or to is None:
        return LineBoost()
    return LineBoost(str(code), rates, to, texts["source"], texts["unverified"])


def _parse_limits(chk: Checker, raw: dict[str, Any] | None) -> Limits:
    if raw is None:
        return Limits()
    chk.known_keys(raw, LIMITS_KEYS, "limits")
    return Limits(
        max_read=chk.whole(raw, "max_read", "limits", 1, 125, 125, required=True),
        max_write=chk.whole(raw, "max_write", "limits", 1, 123, 123, required=True),
        write_multiple=chk.opt(raw, "write_multiple", "limits", bool, True),
    )


def _parse_persistence(chk: Checker, raw: dict[str, Any] | None) -> Persistence:
    """How writes reach EEPROM; the switch's code is checked against the entries later (_check_switch)."""
    if raw is None:
        return Persistence()
    chk.known_keys(raw, PERSISTENCE_KEYS, "persistence")
    before = len(chk.problems)
    mode = chk.choice(raw, "mode", "persistence", PERSISTENCE, "immediate", required=True)
    mode_ok = len(chk.problems) == before
    write_limit = chk.opt(raw, "write_limit", "persistence", int, None)
    if write_limit is not None and write_limit < 1:
        chk.bad("persistence.write_limit", f"{write_limit} is not a number of write cycles (1 or more)")
    note = chk.opt(raw, "note", "persistence", str, "")
    switch = _section(chk, raw, "switch", required=False, loc="persistence.switch")
    if mode == "switchable" and "switch" not in raw:
        chk.bad("persistence", "mode 'switchable' needs switch: {code, eeprom, ram}")
    if switch is None or mode != "switchable":
        if switch is not None and mode_ok:
            chk.bad("persistence.switch", f"is for mode 'switchable' (mode is '{mode}')")
        return Persistence(mode=mode, write_limit=write_limit, note=note)
    loc = "persistence.switch"
    chk.known_keys(switch, SWITCH_KEYS, loc)
    persistence = Persistence(
        mode=mode,
        switch_code=chk.need(switch, "code", loc, str) or "",
        switch_eeprom=chk.whole(switch, "eeprom", loc, 0, 0xFFFF, 0, required=True),
        switch_ram=chk.whole(switch, "ram", loc, 0, 0xFFFF, 1, required=True),
        switch_digit=chk.opt(switch, "digit", loc, str, ""),
        write_limit=write_limit,
        note=note,
    )
    if persistence.switch_eeprom == persistence.switch_ram:
        chk.bad(loc, f"eeprom and ram are both {persistence.switch_ram}: the two states need different values")
    return persistence


def _parse_motor(chk: Checker, raw: dict[str, Any] | None) -> Motor | None:
    if raw is None:
        return None
    chk.known_keys(raw, MOTOR_KEYS, "motor")
    before = len(chk.problems)
    vals = {}
    for key in ("rated_torque_nm", "rated_speed_rpm", "max_speed_rpm", "rotor_inertia_kgcm2"):
        v = chk.need(raw, key, "motor", (int, float))
        if v is not None and not 1e-9 <= v <= 1e9:
            chk.bad(f"motor.{key}", f"{shown(v)} is not a number > 0 (1e-9..1e9)")
            v = None
        vals[key] = float(v or 1.0)
    cpr = chk.whole(raw, "counts_per_rev", "motor", 1, 1 << 32, 131072, required=True)
    source = chk.opt(raw, "source", "motor", str, "")
    if len(chk.problems) == before and vals["max_speed_rpm"] < vals["rated_speed_rpm"]:
        chk.bad("motor.max_speed_rpm", f"{vals['max_speed_rpm']:g} is below rated_speed_rpm")
    return Motor(counts_per_rev=cpr, source=source, **vals)
