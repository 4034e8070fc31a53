"""Validating one profile entry: keys, types, ranges, digit fields, and overlaps between entries."""

from __future__ import annotations

import math
from typing import Any

from servotool.model.checker import Checker, int_map
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


def _typed_range(type_name: str) -> tuple[int, int]:
    words, signed = TYPES[type_name]
    bits = 16 * words
    return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)


def _parse_fields(
    chk: Checker, raw: dict[str, Any], loc: str, fmt: str, fields: list[str], width: int, default: int | None
) -> tuple[dict[str, tuple[int, int]], dict[str, dict[int, str]]]:
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
                enums[str(name).upper()] = int_map(chk, value, where)
                continue
            ok = (
                isinstance(value, list)
                and len(value) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
            )
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


def _check_packed_range(
    chk: Checker, loc: str, fields: list[str], width: int, ranges: dict[str, tuple[int, int]], vmin: int, vmax: int
) -> None:
    """min/max must admit every value the field ranges allow, or a valid field value fails with a packed-range
    message nobody can read."""
    limit = 99 if width == 8 else 15
    lows = sum(ranges.get(f.upper(), (0, limit))[0] << (width * i) for i, f in enumerate(fields))
    highs = sum(ranges.get(f.upper(), (0, limit))[1] << (width * i) for i, f in enumerate(fields))
    if vmin > lows or vmax < highs:
        chk.bad(
            loc,
            f"min/max 0x{vmin:04X}..0x{vmax:04X} exclude field values the field ranges allow "
            f"(need min <= 0x{lows:04X}, max >= 0x{highs:04X})",
        )


def parse_entry(chk: Checker, raw: Any, index: int, word_order: str) -> Entry | None:
    loc = f"entries[{index}]"
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping")
        return None
    if isinstance(raw.get("code"), str):
        loc = f"entries[{index}] ({raw['code']})"
    chk.known_keys(raw, ENTRY_KEYS, loc)
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
    bits = int_map(chk, raw.get("bits"), f"{loc}.bits")
    enum = int_map(chk, raw.get("enum"), f"{loc}.enum")
    combine = chk.choice(raw, "combine", loc, ("binary", "decimal"), "binary")
    digits = chk.opt(raw, "digits", loc, int, 5)
    trigger = chk.opt(raw, "trigger", loc, int, 1)
    copy = chk.opt(raw, "copy", loc, bool, True)
    unverified = _reason(chk, raw, loc)
    if address is not None and not 0 <= address <= 0xFFFF:
        chk.bad(f"{loc}.address", f"{address} is outside 0..65535")
    scale = _check_scale(chk, loc, scale)
    _check_range(chk, loc, type_name, vmin, vmax, default)
    _check_kind(chk, loc, raw, cls, access, default)
    _check_format(chk, loc, fmt, fields, field_width, bits)
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
        code=code,
        cls=cls,
        name=name,
        address=address,
        type=type_name,
        word_order=chk.choice(raw, "word_order", loc, WORD_ORDERS, word_order),
        combine=combine,
        digits=digits,
        scale=float(scale),
        unit=str(raw.get("unit", "") or ""),
        min=vmin,
        max=vmax,
        default=default,
        access=access,
        effect=effect,
        group=str(raw.get("group", "") or ""),
        description=str(raw.get("description", "") or ""),
        source=source,
        unverified=unverified,
        format=fmt,
        fields=tuple(str(f) for f in fields),
        field_width=field_width,
        field_ranges=field_ranges,
        field_enums=field_enums,
        bits=bits,
        enum=enum,
        trigger=trigger,
        copy=copy,
    )


def _reason(chk: Checker, raw: dict[str, Any], loc: str) -> str:
    """Why an entry is unverified ("" when it is not)."""
    unverified = raw.get("unverified", "")
    if unverified is True:
        chk.bad(f"{loc}.unverified", "give the reason as a string, not just 'true'")
        return "unverified"
    return str(unverified or "")


def _check_scale(chk: Checker, loc: str, scale: float) -> float:
    if not (math.isfinite(scale) and 1e-9 <= scale <= 1e9):
        chk.bad(f"{loc}.scale", "must be a finite number > 0 (1e-9..1e9)")
        return 1.0
    return scale


def _check_range(chk: Checker, loc: str, type_name: str, vmin: int, vmax: int, default: int | None) -> None:
    lo, hi = _typed_range(type_name)
    if not lo <= vmin <= hi or not lo <= vmax <= hi:
        chk.bad(loc, f"min/max {vmin}..{vmax} outside the {type_name} range {lo}..{hi}")
    if vmin > vmax:
        chk.bad(loc, f"min {vmin} > max {vmax}")
    if default is not None and not vmin <= default <= vmax:
        chk.bad(f"{loc}.default", f"{default} outside min..max {vmin}..{vmax}")


def _check_kind(chk: Checker, loc: str, raw: dict[str, Any], cls: str, access: str, default: int | None) -> None:
    """What an entry's class asks of it."""
    if cls == "Pn":
        if default is None:
            chk.bad(loc, "Pn entry needs 'default'")
        if "effect" not in raw:
            chk.bad(loc, "Pn entry needs 'effect'")
    if cls == "Un" and access != "ro":
        chk.bad(f"{loc}.access", "Un entries are read-only")


def _check_format(chk: Checker, loc: str, fmt: str, fields: list[Any], field_width: int, bits: dict[int, str]) -> None:
    """What an entry's display format asks of it."""
    if fmt == "digits" and not fields:
        chk.bad(loc, "format: digits needs 'fields'")
    if fmt == "digits" and field_width not in (4, 8):
        chk.bad(f"{loc}.field_width", "must be 4 or 8")
    if fmt == "bits" and not bits:
        chk.bad(loc, "format: bits needs 'bits'")


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
