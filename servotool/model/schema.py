"""Profile schema validation: every problem of a YAML profile with its location (see profiles/SCHEMA.md)."""

from __future__ import annotations

from typing import Any

from servotool.model.profile import (
    ACCESS,
    ALARM_KINDS,
    CLASSES,
    CONVENTIONS,
    DEFAULT_ACCESS,
    EFFECTS,
    FORMATS,
    PERSISTENCE,
    TYPES,
    WORD_ORDERS,
    Alarm,
    Entry,
    Limits,
    LineSettings,
    Motor,
    Persistence,
    Profile,
    SetupItem,
)

ENTRY_KEYS = {
    "code", "class", "name", "address", "type", "word_order", "combine", "digits", "scale", "unit", "min",
    "max", "default", "access", "effect", "group", "description", "source", "unverified", "format", "fields",
    "field_width", "field_ranges", "field_enums", "bits", "enum", "trigger", "copy",
}


TOP_KEYS = {
    "schema", "id", "model", "vendor", "version", "description", "source", "address_rule", "serial", "limits",
    "word_order", "persistence", "motor", "unverified_note", "groups", "roles", "entries", "alarms", "conventions",
    "motion_setup",
}


SETUP_KEYS = {"code", "value", "reason", "source", "unverified"}


def _typed_range(type_name: str) -> tuple[int, int]:
    words, signed = TYPES[type_name]
    bits = 16 * words
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)


class _Checker:
    """Collects every problem with its location instead of stopping at the first."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.problems: list[str] = []

    def bad(self, loc: str, msg: str) -> None:
        self.problems.append(f"{self.where}: {loc}: {msg}")

    def need(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...]) -> Any:
        if key not in data or data[key] is None:
            self.bad(loc, f"missing required key '{key}'")
            return None
        value = data[key]
        if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
            self.bad(f"{loc}.{key}", f"expected {_kind_name(kind)}, got {value!r}")
            return None
        return value

    def opt(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...], default: Any) -> Any:
        if key not in data or data[key] is None:
            return default
        value = data[key]
        if not isinstance(value, kind) or (isinstance(value, bool) and kind not in (bool, (bool,))):
            self.bad(f"{loc}.{key}", f"expected {_kind_name(kind)}, got {value!r}")
            return default
        return value

    def choice(self, data: dict[str, Any], key: str, loc: str, allowed: tuple[str, ...], default: str) -> str:
        value = data.get(key, default)
        if value is None:
            return default
        if value not in allowed:
            self.bad(f"{loc}.{key}", f"'{value}' is not one of {', '.join(allowed)}")
            return default
        return str(value)


def _kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {int: "an integer", float: "a number", str: "a string", dict: "a mapping", list: "a list",
             bool: "true/false"}
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def _int_map(chk: _Checker, raw: Any, loc: str) -> dict[int, str]:
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping of integer -> name")
        return {}
    out: dict[int, str] = {}
    for k, v in raw.items():
        if not isinstance(k, int) or isinstance(k, bool):
            chk.bad(loc, f"key {k!r} is not an integer")
            continue
        out[k] = str(v)
    return out


def _parse_fields(chk: _Checker, raw: dict[str, Any], loc: str, fmt: str, fields: list[str], width: int,
                  default: int | None) -> tuple[dict[str, tuple[int, int]], dict[str, dict[int, str]]]:
    """field_ranges / field_enums of a digit entry: known field names, ranges within the panel's digits, the
    default's fields inside their ranges."""
    ranges: dict[str, tuple[int, int]] = {}
    enums: dict[str, dict[int, str]] = {}
    given = [k for k in ("field_ranges", "field_enums") if raw.get(k) is not None]
    if not given:
        return ranges, enums
    if fmt != "digits":
        chk.bad(loc, f"{', '.join(given)} needs format: digits")
        return ranges, enums
    names = {f.upper(): f for f in fields}
    limit = 99 if width == 8 else 15
    for key in given:
        if not isinstance(raw[key], dict):
            chk.bad(f"{loc}.{key}", "expected a mapping of field name -> value")
            continue
        for name, value in raw[key].items():
            where = f"{loc}.{key}.{name}"
            if str(name).upper() not in names:
                chk.bad(where, f"unknown field (fields: {', '.join(fields)})")
                continue
            if key == "field_enums":
                enums[str(name).upper()] = _int_map(chk, value, where)
                continue
            ok = isinstance(value, list) and len(value) == 2 and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value)
            if not ok or not 0 <= value[0] <= value[1] <= limit:
                chk.bad(where, f"expected [lo, hi] with 0 <= lo <= hi <= {limit}")
                continue
            ranges[str(name).upper()] = (value[0], value[1])
    if default is not None and width in (4, 8):
        mask = (1 << width) - 1
        for i, f in enumerate(fields):
            v = default >> (width * i) & mask
            lo, hi = ranges.get(f.upper(), (0, limit))
            if not lo <= v <= hi:
                chk.bad(f"{loc}.default", f"field {f}={v} outside its range {lo}..{hi}")
    return ranges, enums


def _check_packed_range(chk: _Checker, loc: str, fields: list[str], width: int,
                        ranges: dict[str, tuple[int, int]], vmin: int, vmax: int) -> None:
    """min/max must admit every value the field ranges allow, or a valid field value fails with a packed-range
    message nobody can read."""
    limit = 99 if width == 8 else 15
    lows = sum(ranges.get(f.upper(), (0, limit))[0] << (width * i) for i, f in enumerate(fields))
    highs = sum(ranges.get(f.upper(), (0, limit))[1] << (width * i) for i, f in enumerate(fields))
    if vmin > lows or vmax < highs:
        chk.bad(loc, f"min/max 0x{vmin:04X}..0x{vmax:04X} exclude field values the field ranges allow "
                     f"(need min <= 0x{lows:04X}, max >= 0x{highs:04X})")


def _parse_entry(chk: _Checker, raw: Any, index: int, word_order: str) -> Entry | None:
    loc = f"entries[{index}]"
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping")
        return None
    if isinstance(raw.get("code"), str):
        loc = f"entries[{index}] ({raw['code']})"
    for key in raw:
        if key not in ENTRY_KEYS:
            chk.bad(loc, f"unknown key '{key}'")
    before = len(chk.problems)
    code = chk.need(raw, "code", loc, str)
    cls = chk.choice(raw, "class", loc, CLASSES, "")
    if "class" not in raw:
        chk.bad(loc, "missing required key 'class'")
    name = chk.need(raw, "name", loc, str)
    address = chk.need(raw, "address", loc, int)
    source = chk.need(raw, "source", loc, str)
    type_name = chk.choice(raw, "type", loc, tuple(TYPES), "u16")
    lo, hi = _typed_range(type_name)
    access = chk.choice(raw, "access", loc, ACCESS, DEFAULT_ACCESS.get(cls, "rw"))
    effect = chk.choice(raw, "effect", loc, EFFECTS, "unknown")
    fmt = chk.choice(raw, "format", loc, FORMATS, "dec")
    scale = chk.opt(raw, "scale", loc, (int, float), 1.0)
    vmin = chk.opt(raw, "min", loc, int, lo)
    vmax = chk.opt(raw, "max", loc, int, hi)
    default = chk.opt(raw, "default", loc, int, None)
    fields = chk.opt(raw, "fields", loc, list, [])
    field_width = chk.opt(raw, "field_width", loc, int, 4)
    bits = _int_map(chk, raw.get("bits"), f"{loc}.bits")
    enum = _int_map(chk, raw.get("enum"), f"{loc}.enum")
    combine = chk.choice(raw, "combine", loc, ("binary", "decimal"), "binary")
    unverified = raw.get("unverified", "")
    if unverified is True:
        chk.bad(f"{loc}.unverified", "give the reason as a string, not just 'true'")
        unverified = "unverified"
    if address is not None and not 0 <= address <= 0xFFFF:
        chk.bad(f"{loc}.address", f"{address} is outside 0..65535")
    if scale is not None and scale <= 0:
        chk.bad(f"{loc}.scale", "must be > 0")
    if not lo <= vmin <= hi or not lo <= vmax <= hi:
        chk.bad(loc, f"min/max {vmin}..{vmax} outside the {type_name} range {lo}..{hi}")
    if vmin > vmax:
        chk.bad(loc, f"min {vmin} > max {vmax}")
    if default is not None and not vmin <= default <= vmax:
        chk.bad(f"{loc}.default", f"{default} outside min..max {vmin}..{vmax}")
    if cls == "Pn":
        if default is None:
            chk.bad(loc, "Pn entry needs 'default'")
        if "effect" not in raw:
            chk.bad(loc, "Pn entry needs 'effect'")
    if cls in ("Un", "Sn") and access != "ro" and cls == "Un":
        chk.bad(f"{loc}.access", "Un entries are read-only")
    if fmt == "digits" and not fields:
        chk.bad(loc, "format: digits needs 'fields'")
    if fmt == "digits" and field_width not in (4, 8):
        chk.bad(f"{loc}.field_width", "must be 4 or 8")
    if fmt == "bits" and not bits:
        chk.bad(loc, "format: bits needs 'bits'")
    field_ranges, field_enums = _parse_fields(chk, raw, loc, fmt, [str(f) for f in fields], field_width, default)
    if fmt == "digits" and field_width in (4, 8) and fields:
        _check_packed_range(chk, loc, [str(f) for f in fields], field_width, field_ranges, vmin, vmax)
    if enum and default is not None and default not in enum:
        chk.bad(f"{loc}.default", f"{default} is not one of the enum values {sorted(enum)}")
    if combine == "decimal" and TYPES[type_name][0] == 1:
        chk.bad(f"{loc}.combine", "decimal combination needs a multi-word type")
    if len(chk.problems) > before or code is None or address is None or name is None or source is None:
        return None
    return Entry(
        code=code, cls=cls, name=name, address=address, type=type_name,
        word_order=chk.choice(raw, "word_order", loc, WORD_ORDERS, word_order), combine=combine,
        digits=int(raw.get("digits", 5)), scale=float(scale), unit=str(raw.get("unit", "") or ""),
        min=vmin, max=vmax, default=default, access=access, effect=effect, group=str(raw.get("group", "") or ""),
        description=str(raw.get("description", "") or ""), source=source, unverified=str(unverified or ""),
        format=fmt, fields=tuple(str(f) for f in fields), field_width=field_width, field_ranges=field_ranges,
        field_enums=field_enums, bits=bits, enum=enum,
        trigger=int(raw.get("trigger", 1)), copy=bool(raw.get("copy", True)),
    )


def _check_overlaps(chk: _Checker, entries: list[tuple[int, Entry]]) -> None:
    """Duplicate codes and shared addresses; i is the entry's position in the file's list."""
    seen_codes: dict[str, int] = {}
    owner: dict[int, str] = {}
    for i, e in entries:
        key = e.code.upper()
        if key in seen_codes:
            chk.bad(f"entries[{i}] ({e.code})", f"duplicate code (first at entries[{seen_codes[key]}])")
        seen_codes.setdefault(key, i)
        for addr in e.addresses:
            if addr in owner:
                chk.bad(f"entries[{i}] ({e.code})", f"address {addr} (0x{addr:04X}) overlaps {owner[addr]}")
                break
            owner[addr] = e.code


def parse_profile(data: Any, where: str) -> tuple[Profile | None, list[str]]:
    """Validate parsed YAML; return the profile (None if broken) and every problem found."""
    chk = _Checker(where)
    if not isinstance(data, dict):
        chk.bad("top", "a profile must be a YAML mapping")
        return None, chk.problems
    for key in data:
        if key not in TOP_KEYS:
            chk.bad("top", f"unknown key '{key}'")
    if data.get("schema") != 1:
        chk.bad("schema", f"expected schema: 1, got {data.get('schema')!r}")
    pid = chk.need(data, "id", "top", str)
    texts = {k: chk.need(data, k, "top", str) for k in
             ("model", "vendor", "version", "description", "source", "address_rule")}
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
    raw_entries = data.get("entries")
    if not isinstance(raw_entries, list) or not raw_entries:
        chk.bad("entries", "expected a non-empty list")
        raw_entries = []
    parsed = [(i, e) for i, raw in enumerate(raw_entries) if (e := _parse_entry(chk, raw, i, word_order))]
    _check_overlaps(chk, parsed)
    entries = [e for _, e in parsed]
    codes = {e.code.upper() for e in entries}
    # Codes of entries that are present but broken: references to them are not 'unknown'.
    broken = {str(raw["code"]).upper() for raw in raw_entries if isinstance(raw, dict) and "code" in raw} - codes
    if groups:
        for e in entries:
            if e.group and e.group not in groups:
                chk.bad(f"entry {e.code}", f"group '{e.group}' is not declared in 'groups'")
    roles = data.get("roles") or {}
    if not isinstance(roles, dict):
        chk.bad("roles", "expected a mapping of role -> code")
        roles = {}
    for role, code in roles.items():
        if isinstance(code, str) and code.upper() in broken:
            chk.bad(f"roles.{role}", f"names broken entry {code!r} (see its own problem)")
        elif not isinstance(code, str) or code.upper() not in codes:
            chk.bad(f"roles.{role}", f"names unknown entry {code!r}")
    if persistence.mode == "switchable" and persistence.switch_code.upper() not in codes:
        chk.bad("persistence.switch.code", f"names unknown entry {persistence.switch_code!r}")
    if persistence.mode == "ram" and "eeprom_save" not in roles and not persistence.note:
        chk.bad("persistence.note", "mode 'ram' without role 'eeprom_save' must say how the drive stores values")
    alarms = _parse_alarms(chk, data.get("alarms"))
    conventions = data.get("conventions") or {}
    if not isinstance(conventions, dict):
        chk.bad("conventions", "expected a mapping")
        conventions = {}
    for key, value in conventions.items():
        if key not in CONVENTIONS or value not in CONVENTIONS[key]:
            chk.bad(f"conventions.{key}", f"unknown convention {key}: {value!r}")
    motion_setup = _parse_motion_setup(chk, data.get("motion_setup"), {e.code.upper(): e for e in entries}, broken)
    if chk.problems or pid is None or any(v is None for v in texts.values()):
        return None, chk.problems
    profile = Profile(
        id=pid, model=texts["model"], vendor=texts["vendor"], version=texts["version"],
        description=texts["description"], source=texts["source"], address_rule=texts["address_rule"],
        line=line, default_unit=default_unit, limits=limits, word_order=word_order, persistence=persistence,
        motor=motor,
        entries=entries, roles={str(k): str(v) for k, v in roles.items()},
        groups={str(k): str(v) for k, v in groups.items()}, alarms=alarms,
        conventions={str(k): str(v) for k, v in conventions.items()}, motion_setup=motion_setup,
        unverified_note=str(data.get("unverified_note", "")),
    )
    return profile, []


def _parse_motion_setup(chk: _Checker, raw: Any, entries: dict[str, Entry], broken: set[str]) -> list[SetupItem]:
    """motion_setup: known writable Pn codes, each value valid for its entry (parsed as `param set` would)."""
    from servotool.errors import ServoError
    from servotool.model.setup import requirement

    out: list[SetupItem] = []
    seen: set[str] = set()
    for loc, item in _mappings(chk, raw, "motion_setup", "{code, value, reason, source}"):
        for key in item:
            if key not in SETUP_KEYS:
                chk.bad(loc, f"unknown key '{key}'")
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
            chk.bad(f"{loc}.code", f"{entry.code} is not a settable parameter (class {entry.cls}, "
                                   f"access {entry.access})")
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


def _mappings(chk: _Checker, raw: Any, name: str, shape: str = "") -> list[tuple[str, dict[str, Any]]]:
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


def _parse_alarms(chk: _Checker, raw: Any) -> list[Alarm]:
    out: list[Alarm] = []
    seen: set[int] = set()
    for loc, item in _mappings(chk, raw, "alarms"):
        code = chk.need(item, "code", loc, int)
        name = chk.need(item, "name", loc, str)
        kind = chk.choice(item, "kind", loc, ALARM_KINDS, "other")
        if code is None or name is None:
            continue
        if code in seen:
            chk.bad(loc, f"duplicate alarm code {code}")
        seen.add(code)
        out.append(Alarm(code=code, display=str(item.get("display", code)), name=name,
                         clearable=bool(item.get("clearable", True)), kind=kind, source=str(item.get("source", ""))))
    return out


def _parse_serial(chk: _Checker, raw: Any) -> tuple[LineSettings, int]:
    if not isinstance(raw, dict):
        chk.bad("serial", "missing or not a mapping")
        return LineSettings(), 1
    s = LineSettings(
        baud=chk.opt(raw, "baud", "serial", int, 9600),
        parity=chk.choice(raw, "parity", "serial", ("N", "E", "O"), "N"),
        stopbits=chk.opt(raw, "stopbits", "serial", int, 1), bytesize=chk.opt(raw, "bytesize", "serial", int, 8),
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


def _parse_limits(chk: _Checker, raw: Any) -> Limits:
    if not isinstance(raw, dict):
        chk.bad("limits", "missing or not a mapping")
        return Limits()
    lim = Limits(
        max_read=chk.opt(raw, "max_read", "limits", int, 125), max_write=chk.opt(raw, "max_write", "limits", int, 123),
        write_multiple=chk.opt(raw, "write_multiple", "limits", bool, True),
    )
    if not 1 <= lim.max_read <= 125:
        chk.bad("limits.max_read", "must be 1..125")
    if not 1 <= lim.max_write <= 123:
        chk.bad("limits.max_write", "must be 1..123")
    return lim


def _parse_persistence(chk: _Checker, raw: Any) -> Persistence:
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
        mode=mode, switch_code=str(switch.get("code", "")), switch_eeprom=int(switch.get("eeprom", 0)),
        switch_ram=int(switch.get("ram", 1)), switch_digit=str(switch.get("digit", "") or ""),
        write_limit=chk.opt(raw, "write_limit", "persistence", int, None), note=str(raw.get("note", "") or ""),
    )


def _parse_motor(chk: _Checker, raw: Any) -> Motor | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        chk.bad("motor", "expected a mapping")
        return None
    vals = {}
    for key in ("rated_torque_nm", "rated_speed_rpm", "max_speed_rpm", "rotor_inertia_kgcm2"):
        v = chk.need(raw, key, "motor", (int, float))
        if v is not None and v <= 0:
            chk.bad(f"motor.{key}", "must be > 0")
        vals[key] = float(v or 1.0)
    cpr = chk.need(raw, "counts_per_rev", "motor", int) or 131072
    return Motor(counts_per_rev=cpr, source=str(raw.get("source", "") or ""), **vals)
