"""A validated profile as plain JSON data and back: the compiled-profile cache's format.

Data only, so that a cache file that someone else wrote can at worst be refused, never run (the cache was pickle:
a replaced file ran code at the next command). The loader guards the file (content hash, owner); this module
turns what it holds back into the same objects the schema built, and raises ValueError on anything else.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from dataclasses import fields
from typing import Any

from servotool.model.alarm_notes import AlarmCauses, AlarmLog
from servotool.model.profile import (
    Alarm,
    DeadManRoute,
    Entry,
    ForcedInputs,
    Identity,
    IdentityCheck,
    Limits,
    LineBoost,
    LineSettings,
    Motor,
    Persistence,
    Profile,
    SetupItem,
)
from servotool.model.terminals import IoMap

ENTRY_FIELDS = tuple(f.name for f in fields(Entry))
# The sections beyond the register map, as nested frozen dataclasses: stored field by field (_encode) and rebuilt by
# their annotations (_decode), so a field added to one of them is carried without a line here.
SECTIONS: dict[str, Any] = {
    "io": IoMap | None,
    "alarm_causes": AlarmCauses | None,
    "alarm_log": AlarmLog | None,
    "unverified_values": dict[str, str],
    "boost": LineBoost,
}
TEXTS = ("id", "model", "vendor", "version", "description", "source", "address_rule", "word_order", "unverified_note")


def to_data(parsed: tuple[Profile | None, list[str]]) -> dict[str, Any]:
    """What read_profile found (a profile, or None and its problems) as JSON-ready data."""
    profile, problems = parsed
    return {
        "entry_fields": ENTRY_FIELDS,
        "problems": problems,
        "profile": None if profile is None else _profile(profile),
    }


def from_data(data: Any) -> tuple[Profile | None, list[str]]:
    """The inverse of to_data; ValueError when the data is not what to_data makes."""
    try:
        if data["entry_fields"] != list(ENTRY_FIELDS):
            raise ValueError("written for other entry fields")
        problems = data["problems"]
        if not isinstance(problems, list) or not all(isinstance(p, str) for p in problems):
            raise ValueError("problems are not a list of lines")
        return (None if data["profile"] is None else _build(data["profile"])), problems
    except (KeyError, TypeError, AttributeError, IndexError) as exc:
        raise ValueError(f"not a compiled profile: {exc!r}") from None


def _profile(p: Profile) -> dict[str, Any]:
    return {
        **{k: getattr(p, k) for k in TEXTS},
        "default_unit": p.default_unit,
        "line": vars(p.line),
        "limits": vars(p.limits),
        "persistence": vars(p.persistence),
        "motor": None if p.motor is None else vars(p.motor),
        "entries": [_entry_row(e) for e in p.entries],
        "roles": p.roles,
        "groups": p.groups,
        "conventions": p.conventions,
        "alarms": [vars(a) for a in p.alarms],
        "motion_setup": [vars(s) for s in p.motion_setup],
        "dead_man": None if p.dead_man is None else vars(p.dead_man),
        "forced_inputs": None if p.forced_inputs is None else vars(p.forced_inputs),
        **{name: _encode(getattr(p, name)) for name in SECTIONS},
        "identity": None
        if p.identity is None
        else {
            "checks": [vars(c) for c in p.identity.checks],
            "firmware": p.identity.firmware,
            "model": p.identity.model,
        },
    }


def _entry_row(e: Entry) -> list[Any]:
    """An entry as a list in field order (a third of the size of a mapping each); integer-keyed maps as pairs,
    since JSON keys are strings."""
    row = [getattr(e, name) for name in ENTRY_FIELDS]
    for name in ("bits", "enum"):
        row[ENTRY_FIELDS.index(name)] = list(getattr(e, name).items())
    row[ENTRY_FIELDS.index("field_enums")] = {k: list(v.items()) for k, v in e.field_enums.items()}
    return row


_FIELDS_AT, _RANGES_AT, _ENUMS_AT = (ENTRY_FIELDS.index(n) for n in ("fields", "field_ranges", "field_enums"))
_BITS_AT, _ENUM_AT = (ENTRY_FIELDS.index(n) for n in ("bits", "enum"))


def _entry(row: list[Any]) -> Entry:
    """The entry a row stores. Built as unpickling builds it (its fields set directly, not through the frozen
    dataclass's __init__, which takes a third of a 600-entry profile's load time): the values were checked by the
    schema when the row was written, and the loader's hash proves that they are the ones written."""
    if len(row) != len(ENTRY_FIELDS):
        raise ValueError("an entry row of the wrong length")
    row = list(row)
    row[_FIELDS_AT] = tuple(row[_FIELDS_AT])
    row[_RANGES_AT] = {k: (lo, hi) for k, (lo, hi) in row[_RANGES_AT].items()}
    row[_ENUMS_AT] = {k: dict(map(tuple, pairs)) for k, pairs in row[_ENUMS_AT].items()}
    row[_BITS_AT] = dict(map(tuple, row[_BITS_AT]))
    row[_ENUM_AT] = dict(map(tuple, row[_ENUM_AT]))
    entry = object.__new__(Entry)
    entry.__dict__.update(zip(ENTRY_FIELDS, row, strict=True))
    return entry


def _build(p: dict[str, Any]) -> Profile:
    identity = p["identity"]
    return Profile(
        **{k: p[k] for k in TEXTS},
        default_unit=p["default_unit"],
        line=LineSettings(**p["line"]),
        limits=Limits(**p["limits"]),
        persistence=Persistence(**p["persistence"]),
        motor=None if p["motor"] is None else Motor(**p["motor"]),
        entries=[_entry(row) for row in p["entries"]],
        roles=dict(p["roles"]),
        groups=dict(p["groups"]),
        conventions=dict(p["conventions"]),
        alarms=[Alarm(**a) for a in p["alarms"]],
        motion_setup=[SetupItem(**s) for s in p["motion_setup"]],
        dead_man=None if p["dead_man"] is None else DeadManRoute(**p["dead_man"]),
        forced_inputs=None if p["forced_inputs"] is None else ForcedInputs(**p["forced_inputs"]),
        **{name: _decode(kind, p[name]) for name, kind in SECTIONS.items()},
        identity=None
        if identity is None
        else Identity(
            tuple(
                IdentityCheck(**{**c, "range": None if c["range"] is None else tuple(c["range"])})
                for c in identity["checks"]
            ),
            identity["firmware"],
            identity["model"],
        ),
    )


def _encode(value: Any) -> Any:
    """A section's value as JSON data: a dataclass as its fields, a tuple as a list, a mapping as [key, value]
    pairs (its keys may be numbers, which JSON keys are not)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _encode(getattr(value, f.name)) for f in fields(value)}
    if isinstance(value, tuple | list):
        return [_encode(v) for v in value]
    if isinstance(value, dict):
        return [[_encode(k), _encode(v)] for k, v in value.items()]
    return value


def _decode(kind: Any, data: Any) -> Any:
    """The inverse of _encode for a value of the annotated kind; ValueError on data of another shape."""
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (types.UnionType, typing.Union):
        if data is None and type(None) in args:
            return None
        (inner,) = [a for a in args if a is not type(None)]
        return _decode(inner, data)
    if origin is tuple:
        return tuple(_decode(args[0], v) for v in data)
    if origin is dict:
        return {_decode(args[0], k): _decode(args[1], v) for k, v in data}
    if dataclasses.is_dataclass(kind):
        hints = typing.get_type_hints(kind)
        return kind(**{name: _decode(hints[name], v) for name, v in data.items()})
    if kind in (str, int, float, bool) and isinstance(data, kind) and (kind is bool or not isinstance(data, bool)):
        return data
    raise ValueError(f"not a {kind}: {data!r}")
