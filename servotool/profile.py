"""Drive profile model: load, validate and query a YAML register map (see profiles/SCHEMA.md)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from servotool.errors import ProfileError, UsageError

CLASSES = ("Pn", "Un", "Sn", "Fn")
TYPES = {"u16": (1, False), "s16": (1, True), "u32": (2, False), "s32": (2, True),
         "u64": (4, False), "s64": (4, True)}
ACCESS = ("rw", "ro", "wo")
EFFECTS = ("immediate", "servo_off", "power_cycle", "unknown")
FORMATS = ("dec", "hex", "digits", "bits")
WORD_ORDERS = ("low_first", "high_first")
PERSISTENCE = ("immediate", "ram", "switchable")
DEFAULT_ACCESS = {"Pn": "rw", "Un": "ro", "Sn": "ro", "Fn": "wo"}

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
ALARM_KINDS = ("overspeed", "overload", "following_error", "comm_timeout", "inertia_id_failed", "other")
CONVENTIONS = {"inertia_ratio": ("load_over_motor", "total_over_motor")}


@dataclass(frozen=True)
class Entry:
    """One register-mapped item of a drive."""

    code: str
    cls: str
    name: str
    address: int
    type: str = "u16"
    word_order: str = "low_first"
    combine: str = "binary"
    digits: int = 5
    scale: float = 1.0
    unit: str = ""
    min: int = 0
    max: int = 0
    default: int | None = None
    access: str = "rw"
    effect: str = "unknown"
    group: str = ""
    description: str = ""
    source: str = ""
    unverified: str = ""
    format: str = "dec"
    fields: tuple[str, ...] = ()
    field_width: int = 4
    field_ranges: dict[str, tuple[int, int]] = field(default_factory=dict)   # upper-case field name -> (lo, hi)
    field_enums: dict[str, dict[int, str]] = field(default_factory=dict)     # upper-case field name -> meanings
    bits: dict[int, str] = field(default_factory=dict)
    enum: dict[int, str] = field(default_factory=dict)
    trigger: int = 1
    copy: bool = True

    @property
    def words(self) -> int:
        """Number of 16-bit registers the entry occupies."""
        return TYPES[self.type][0]

    @property
    def signed(self) -> bool:
        return TYPES[self.type][1]

    @property
    def readable(self) -> bool:
        return self.access in ("rw", "ro")

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")

    @property
    def addresses(self) -> range:
        return range(self.address, self.address + self.words)


@dataclass(frozen=True)
class Serial:
    baud: int = 9600
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8
    unit: int = 1


@dataclass(frozen=True)
class Limits:
    max_read: int = 125
    max_write: int = 123
    write_multiple: bool = True


@dataclass(frozen=True)
class Persistence:
    mode: str = "immediate"
    switch_code: str = ""
    switch_eeprom: int = 0
    switch_ram: int = 1
    switch_digit: str = ""
    write_limit: int | None = None
    note: str = ""

    def is_switch(self, code: str) -> bool:
        """Whether code is the RAM/EEPROM switch of a switchable drive."""
        return bool(self.switch_code) and code.upper() == self.switch_code.upper()


@dataclass(frozen=True)
class Motor:
    rated_torque_nm: float = 1.27
    rated_speed_rpm: float = 3000.0
    max_speed_rpm: float = 6000.0
    rotor_inertia_kgcm2: float = 0.33
    counts_per_rev: int = 131072
    source: str = ""

    @property
    def jm(self) -> float:
        """Rotor inertia in kg*m^2."""
        return self.rotor_inertia_kgcm2 * 1e-4


@dataclass(frozen=True)
class Alarm:
    """One alarm/fault code the drive reports."""

    code: int
    display: str
    name: str
    clearable: bool = True
    kind: str = "other"
    source: str = ""


@dataclass(frozen=True)
class SetupItem:
    """A setting the drive needs before host motion works (motion_setup): value as users type it."""

    code: str
    value: str
    reason: str
    source: str
    unverified: str = ""


@dataclass
class Profile:
    """A loaded, validated drive profile."""

    id: str
    model: str
    vendor: str
    version: str
    description: str
    source: str
    address_rule: str
    serial: Serial
    limits: Limits
    word_order: str
    persistence: Persistence
    motor: Motor | None
    entries: list[Entry]
    roles: dict[str, str]
    groups: dict[str, str]
    alarms: list[Alarm] = field(default_factory=list)
    conventions: dict[str, str] = field(default_factory=dict)
    motion_setup: list[SetupItem] = field(default_factory=list)
    unverified_note: str = ""
    path: Path | None = None
    _by_code: dict[str, Entry] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._by_code = {e.code.upper(): e for e in self.entries}

    def entry(self, code: str) -> Entry:
        """The entry with this vendor code (case-insensitive) or role name."""
        found = self.find(code)
        if found is None:
            raise UsageError(f"unknown code '{code}' for profile {self.id} (see 'servotool param list')")
        return found

    def find(self, code: str) -> Entry | None:
        hit = self._by_code.get(code.strip().upper())
        if hit is None and code in self.roles:
            hit = self._by_code.get(self.roles[code].upper())
        return hit

    def role(self, name: str) -> Entry | None:
        """The entry a semantic role maps to, or None when the profile lacks it."""
        code = self.roles.get(name)
        return self._by_code.get(code.upper()) if code else None

    def need_role(self, name: str, feature: str) -> Entry:
        """The entry for a role a feature cannot do without."""
        hit = self.role(name)
        if hit is None:
            raise UsageError(f"{feature} needs role '{name}', which profile {self.id} does not map")
        return hit

    def of_class(self, *classes: str) -> list[Entry]:
        return [e for e in self.entries if e.cls in classes]

    def alarm(self, code: int) -> Alarm | None:
        return next((a for a in self.alarms if a.code == code), None)

    def alarm_of_kind(self, kind: str) -> Alarm | None:
        return next((a for a in self.alarms if a.kind == kind), None)

    def load_ratio_from_param(self, eng: float) -> float:
        """J_load/J_motor from the inertia-ratio parameter's engineering value, per the profile's convention."""
        entry = self.need_role("inertia_ratio", "inertia ratio conversion")
        ratio = eng / 100.0 if entry.unit == "%" else float(eng)
        if self.conventions.get("inertia_ratio") == "total_over_motor":
            ratio -= 1.0
        return ratio

    def param_from_load_ratio(self, load_ratio: float) -> float:
        """Engineering value of the inertia-ratio parameter for a J_load/J_motor ratio."""
        entry = self.need_role("inertia_ratio", "inertia ratio conversion")
        ratio = load_ratio + 1.0 if self.conventions.get("inertia_ratio") == "total_over_motor" else load_ratio
        return ratio * 100.0 if entry.unit == "%" else ratio


# Status-word bit names by meaning: servotool's own names and the vendors' DO-function mnemonics (SD25 SON-O,
# ALM, TGON), so one status role works whatever the drive calls its bits.
STATUS_ALIASES = {"servo_on": ("servo_on", "son", "son-o", "run"), "fault": ("fault", "alm"),
                  "moving": ("moving", "tgon"), "jog": ("jog",), "identifying": ("identifying",)}


def status_bit(entry: Entry, meaning: str) -> int | None:
    """The bit of a status entry (format: bits) that carries a meaning (see STATUS_ALIASES), or None."""
    names = STATUS_ALIASES.get(meaning, (meaning,))
    return next((bit for bit, name in sorted(entry.bits.items()) if name.lower() in names), None)


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
    serial = _parse_serial(chk, data.get("serial"))
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
        serial=serial, limits=limits, word_order=word_order, persistence=persistence, motor=motor,
        entries=entries, roles={str(k): str(v) for k, v in roles.items()},
        groups={str(k): str(v) for k, v in groups.items()}, alarms=alarms,
        conventions={str(k): str(v) for k, v in conventions.items()}, motion_setup=motion_setup,
        unverified_note=str(data.get("unverified_note", "")),
    )
    return profile, []


def _parse_motion_setup(chk: _Checker, raw: Any, entries: dict[str, Entry], broken: set[str]) -> list[SetupItem]:
    """motion_setup: known writable Pn codes, each value valid for its entry (parsed as `param set` would)."""
    from servotool.errors import ServoError
    from servotool.prereq import requirement

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


def _parse_serial(chk: _Checker, raw: Any) -> Serial:
    if not isinstance(raw, dict):
        chk.bad("serial", "missing or not a mapping")
        return Serial()
    s = Serial(
        baud=chk.opt(raw, "baud", "serial", int, 9600),
        parity=chk.choice(raw, "parity", "serial", ("N", "E", "O"), "N"),
        stopbits=chk.opt(raw, "stopbits", "serial", int, 1), bytesize=chk.opt(raw, "bytesize", "serial", int, 8),
        unit=chk.opt(raw, "unit", "serial", int, 1),
    )
    if s.baud <= 0:
        chk.bad("serial.baud", "must be positive")
    if s.stopbits not in (1, 2):
        chk.bad("serial.stopbits", "must be 1 or 2")
    if s.bytesize not in (7, 8):
        chk.bad("serial.bytesize", "must be 7 or 8")
    if not 0 <= s.unit <= 247:
        chk.bad("serial.unit", "must be 0..247")
    return s


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


def builtin_dir() -> Path:
    """Folder of the profiles shipped with the package (or, in a source checkout, the top-level profiles/)."""
    here = Path(__file__).resolve().parent
    installed = here / "profiles"
    return installed if installed.is_dir() else here.parent / "profiles"


def builtin_ids() -> list[str]:
    return sorted(p.stem for p in builtin_dir().glob("*.yaml"))


def read_profile(path: Path) -> tuple[Profile | None, list[str]]:
    """Parse a profile file; return it (or None) and the list of problems."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        return None, [f"{path}: cannot read: {exc.strerror or exc}"]
    except UnicodeDecodeError as exc:
        return None, [f"{path}: not UTF-8 text (byte {exc.start})"]
    try:
        data = yaml.load(text, Loader=_SAFE_LOADER)  # safe loader (C-accelerated when available)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark else "?"
        return None, [f"{path}: {where}: invalid YAML: {getattr(exc, 'problem', exc)}"]
    profile, problems = parse_profile(data, str(path))
    if profile is not None:
        profile.path = path
        if profile.id != path.stem:
            return None, [f"{path}: id: '{profile.id}' does not match the file name '{path.stem}'"]
    return profile, problems


_CACHE: dict[str, Profile] = {}
_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def load_profile(name_or_path: str | Path) -> Profile:
    """Load a built-in profile by id, or a profile file by path; raise ProfileError if broken."""
    key = str(name_or_path)
    if key in _CACHE:
        return _CACHE[key]
    path = Path(key)
    # A bare name is a built-in profile id; a path names a file (even a missing one, for a clear error).
    if path.suffix not in (".yaml", ".yml") and "/" not in key and "\\" not in key:
        path = builtin_dir() / f"{key.lower()}.yaml"
        if not path.exists():
            known = ", ".join(builtin_ids())
            raise ProfileError(f"unknown profile '{key}' (built-in: {known}; or give a path to a .yaml file)")
    profile, problems = read_profile(path)
    if profile is None:
        more = f" (and {len(problems) - 1} more; run 'servotool profiles check {path}')" if len(problems) > 1 else ""
        raise ProfileError(f"broken profile: {problems[0]}{more}")
    _CACHE[key] = profile
    return profile
