"""Validating one profile entry: each field's type and range, then the rules between fields, and overlaps between
entries."""

from __future__ import annotations

from typing import Any

from servotool.model.checker import Checker, int_map, shown
from servotool.model.profile import (
    ACCESS,
    CLASSES,
    DEFAULT_ACCESS,
    EFFECTS,
    FORMATS,
    TYPES,
    WORD_ORDERS,
    Entry,
)

ENTRY_KEYS = {
    "code",
    "class",
    "name",
    "address",
    "type",
    "word_order",
    "combine",
    "digits",
    "scale",
    "unit",
    "min",
    "max",
    "default",
    "access",
    "effect",
    "group",
    "description",
    "source",
    "unverified",
    "format",
    "fields",
    "field_width",
    "field_ranges",
    "field_enums",
    "bits",
    "enum",
    "trigger",
    "copy",
}

CODE_SEPARATORS = " =,."  # they separate codes, values and fields on the command line (CODE=V, CODE.FIELD, A,B)
DIGIT_KEYS = ("fields", "field_width", "field_ranges", "field_enums")
SCALE_RANGE = (1e-9, 1e9)


def _typed_range(type_name: str) -> tuple[int, int]:
    words, signed = TYPES[type_name]
    bits = 16 * words
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)


def parse_entry(chk: Checker, raw: Any, index: int, word_order: str) -> Entry | None:
    """The entry, or None after reporting why: each field of the wrong type or outside its own range (a line
    each), else the first rule between fields it breaks (one line: a value breaking one rule often breaks the next,
    and the author fixes them one at a time)."""
    loc = f"entries[{index}]"
    if not isinstance(raw, dict):
        chk.bad(loc, f"expected a mapping, got {shown(raw)}")
        return None
    if isinstance(raw.get("code"), str) and raw["code"].strip():
        loc = f"entries[{index}] ({raw['code']})"
    chk.known_keys(raw, ENTRY_KEYS, loc)
    before = len(chk.problems)
    values = _typed_fields(chk, raw, loc, word_order)
    if len(chk.problems) > before:
        return None
    broken = _rule_broken(values, raw)
    if broken is not None:
        key, msg = broken
        chk.bad(f"{loc}.{key}" if key else loc, msg)
        return None
    return Entry(**values)


def _typed_fields(chk: Checker, raw: dict[str, Any], loc: str, word_order: str) -> dict[str, Any]:
    """Every field as Entry takes it, each checked alone (type, and the range it has whatever the other fields
    say); a broken field's problem is reported and a harmless stand-in returned."""
    before = len(chk.problems)
    type_name = chk.choice(raw, "type", loc, tuple(TYPES), "u16")
    # With a broken type, min/max/enum/trigger are not also blamed for the u16 range it was replaced by.
    lo, hi = _typed_range(type_name) if len(chk.problems) == before else (-(1 << 63), (1 << 64) - 1)
    span = f"the {type_name} range"
    cls = chk.choice(raw, "class", loc, CLASSES, "Pn", required=True)
    return {
        "code": _code(chk, raw, loc),
        "cls": cls,
        "name": chk.need(raw, "name", loc, str),
        "address": chk.whole(raw, "address", loc, 0, 0xFFFF, 0, required=True),
        "type": type_name,
        "word_order": chk.choice(raw, "word_order", loc, WORD_ORDERS, word_order),
        "combine": chk.choice(raw, "combine", loc, ("binary", "decimal"), "binary"),
        "digits": chk.whole(raw, "digits", loc, 1, 5, 5),
        "scale": _scale(chk, raw, loc),
        "unit": chk.opt(raw, "unit", loc, str, ""),
        "min": chk.whole(raw, "min", loc, lo, hi, lo, what=span),
        "max": chk.whole(raw, "max", loc, lo, hi, hi, what=span),
        "default": chk.opt(raw, "default", loc, int, None),
        "access": chk.choice(raw, "access", loc, ACCESS, DEFAULT_ACCESS[cls]),
        "effect": chk.choice(raw, "effect", loc, EFFECTS, "unknown"),
        "group": chk.opt(raw, "group", loc, str, ""),
        "description": chk.opt(raw, "description", loc, str, ""),
        "source": chk.need(raw, "source", loc, str),
        "unverified": _reason(chk, raw, loc),
        "format": chk.choice(raw, "format", loc, FORMATS, "dec"),
        "fields": _field_names(chk, raw, loc),
        "field_width": chk.opt(raw, "field_width", loc, int, 4),
        "field_ranges": _field_ranges(chk, raw, loc),
        "field_enums": _field_enums(chk, raw, loc),
        "bits": int_map(chk, raw["bits"], f"{loc}.bits", 0, 16 * TYPES[type_name][0] - 1) if "bits" in raw else {},
        "enum": int_map(chk, raw["enum"], f"{loc}.enum", lo, hi) if "enum" in raw else {},
        "trigger": chk.whole(raw, "trigger", loc, lo, hi, 1, what=span),
        "copy": chk.opt(raw, "copy", loc, bool, True),
    }


def _code(chk: Checker, raw: dict[str, Any], loc: str) -> str:
    code = chk.need(raw, "code", loc, str)
    if code is not None and any(c in code for c in CODE_SEPARATORS):
        chk.bad(f"{loc}.code", f"{shown(code)} has a space, '=', ',' or '.' (they separate codes on the command line)")
    return code or ""


def _scale(chk: Checker, raw: dict[str, Any], loc: str) -> float:
    scale = chk.opt(raw, "scale", loc, (int, float), 1.0)
    if not SCALE_RANGE[0] <= scale <= SCALE_RANGE[1]:
        chk.bad(f"{loc}.scale", f"{shown(scale)} is not a number > 0 ({SCALE_RANGE[0]:g}..{SCALE_RANGE[1]:g})")
        return 1.0
    return float(scale)


def _reason(chk: Checker, raw: dict[str, Any], loc: str) -> str:
    """Why an entry is unverified ("" when it is not)."""
    if raw.get("unverified") is True:
        chk.bad(f"{loc}.unverified", "give the reason as a string, not just 'true'")
        return "unverified"
    return str(chk.opt(raw, "unverified", loc, str, ""))


def _field_names(chk: Checker, raw: dict[str, Any], loc: str) -> tuple[str, ...]:
    names = chk.opt(raw, "fields", loc, list, [])
    ok = all(isinstance(n, str) and n.strip() and n.isidentifier() for n in names)
    if not ok or len({n.upper() for n in names}) != len(names):
        chk.bad(f"{loc}.fields", f"expected different field names (letters), got {shown(names)}")
        return ()
    return tuple(names)


def _field_ranges(chk: Checker, raw: dict[str, Any], loc: str) -> dict[str, tuple[int, int]]:
    """field_ranges: field name -> [lo, hi] (upper-case names; whether they are fields is a rule between fields)."""
    ranges: dict[str, tuple[int, int]] = {}
    for name, value in _field_mapping(chk, raw, "field_ranges", loc).items():
        ok = isinstance(value, list) and len(value) == 2
        ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in value) and 0 <= value[0] <= value[1]
        if not ok:
            chk.bad(f"{loc}.field_ranges.{name}", f"expected [lo, hi] with 0 <= lo <= hi, got {shown(value)}")
            continue
        ranges[name.upper()] = (value[0], value[1])
    return ranges


def _field_enums(chk: Checker, raw: dict[str, Any], loc: str) -> dict[str, dict[int, str]]:
    mapping = _field_mapping(chk, raw, "field_enums", loc)
    return {name.upper(): int_map(chk, value, f"{loc}.field_enums.{name}", 0, 99) for name, value in mapping.items()}


def _field_mapping(chk: Checker, raw: dict[str, Any], key: str, loc: str) -> dict[str, Any]:
    if key not in raw:
        return {}
    value = raw[key]
    if not isinstance(value, dict) or not value or not all(isinstance(k, str) for k in value):
        chk.bad(f"{loc}.{key}", f"expected a mapping of field name -> value, got {shown(value)}")
        return {}
    return value


# ----- rules between fields --------------------------------------------------------------------------------------


def _rule_broken(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    """The first rule between an entry's fields that it breaks: (the field to blame, or "", and what is wrong)."""
    for rule in (_range_rule, _kind_rule, _words_rule, _format_rule, _enum_rule, _digit_rule):
        broken = rule(v, raw)
        if broken is not None:
            return broken
    return None


def _range_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    if v["min"] > v["max"]:
        return "min", f"{v['min']} is above max {v['max']}"
    default = v["default"]
    if default is not None and not v["min"] <= default <= v["max"]:
        return "default", f"{default} outside min..max {v['min']}..{v['max']}"
    if v["address"] + TYPES[v["type"]][0] - 1 > 0xFFFF:
        return "address", f"{v['address']} leaves no room for the {v['type']}'s words below 65536"
    return None


def _kind_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    """What an entry's class asks of it."""
    if v["cls"] == "Pn" and v["default"] is None:
        return "", "Pn entry needs 'default'"
    if v["cls"] == "Pn" and "effect" not in raw:
        return "", "Pn entry needs 'effect'"
    if v["cls"] == "Un" and v["access"] != "ro":
        return "access", "Un entries are read-only"
    if "trigger" in raw and v["cls"] != "Fn":
        return "trigger", "only Fn entries (functions) have a trigger value"
    return None


def _words_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    if v["combine"] == "decimal" and TYPES[v["type"]][0] == 1:
        return "combine", "decimal combination needs a multi-word type"
    if "digits" in raw and v["combine"] != "decimal":
        return "digits", "digits per word are for combine: decimal"
    return None


def _format_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    """What an entry's display format asks of it."""
    fmt = v["format"]
    if fmt == "digits" and not v["fields"]:
        return "", "format: digits needs 'fields'"
    if fmt == "digits" and v["field_width"] not in (4, 8):
        return "field_width", f"{v['field_width']} is not 4 or 8"
    if fmt != "digits" and (given := [k for k in DIGIT_KEYS if k in raw]):
        return "", f"{', '.join(given)} {'needs' if len(given) == 1 else 'need'} format: digits"
    if fmt == "digits" and len(v["fields"]) * v["field_width"] > 16 * TYPES[v["type"]][0]:
        return "fields", f"{len(v['fields'])} fields of {v['field_width']} bits do not fit a {v['type']}"
    if fmt == "bits" and not v["bits"]:
        return "", "format: bits needs 'bits'"
    if fmt != "bits" and v["bits"]:
        return "bits", "bit names need format: bits"
    return None


def _enum_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    enum = v["enum"]
    if not enum:
        return None
    if outside := [k for k in enum if not v["min"] <= k <= v["max"]]:
        return "enum", f"value {outside[0]} is outside min..max {v['min']}..{v['max']}"
    names = [n.strip().upper() for n in enum.values()]
    if len(set(names)) != len(names):
        return "enum", "two values have the same name (users type the name)"
    if v["default"] is not None and v["default"] not in enum:
        return "default", f"{v['default']} is not one of the enum values {sorted(enum)}"
    return None


def _digit_rule(v: dict[str, Any], raw: dict[str, Any]) -> tuple[str, str] | None:
    """field_ranges / field_enums of a digit entry: known field names, ranges within the panel's digits, the
    default's fields inside their ranges, and min/max admitting every value the field ranges allow (or a valid
    field value fails with a packed-range message nobody can read)."""
    if v["format"] != "digits":
        return None
    fields, width, ranges = v["fields"], v["field_width"], v["field_ranges"]
    names = {f.upper() for f in fields}
    for key in ("field_ranges", "field_enums"):
        if unknown := [n for n in v[key] if n not in names]:
            return f"{key}.{unknown[0]}", f"unknown field (fields: {', '.join(fields)})"
    limit = 99 if width == 8 else 15
    for name, (lo, hi) in ranges.items():
        if hi > limit:
            return f"field_ranges.{name}", f"[{lo}, {hi}]: expected 0 <= lo <= hi <= {limit}"
    mask = (1 << width) - 1
    if v["default"] is not None:
        for i, f in enumerate(fields):
            value = v["default"] >> (width * i) & mask
            lo, hi = ranges.get(f.upper(), (0, limit))
            if not lo <= value <= hi:
                return "default", f"field {f}={value} is outside field_ranges.{f} {lo}..{hi}"
    lows = sum(ranges.get(f.upper(), (0, limit))[0] << (width * i) for i, f in enumerate(fields))
    highs = sum(ranges.get(f.upper(), (0, limit))[1] << (width * i) for i, f in enumerate(fields))
    if v["min"] > lows or v["max"] < highs:
        return "", (
            f"min/max 0x{v['min']:04X}..0x{v['max']:04X} exclude field values the field ranges allow "
            f"(need min <= 0x{lows:04X}, max >= 0x{highs:04X})"
        )
    return None


def check_overlaps(chk: Checker, entries: list[tuple[int, Entry]]) -> None:
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
