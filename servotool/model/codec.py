"""Value conversion: registers <-> raw integers <-> engineering values and text."""

from __future__ import annotations

import math
import re

from servotool.errors import UsageError
from servotool.model.lookup import did_you_mean, enum_value, split_unit, unit_matches
from servotool.model.profile import Entry, Profile


def words_to_raw(entry: Entry, words: list[int]) -> int:
    """Combine the entry's registers into one raw integer (signed per type)."""
    if len(words) != entry.words:
        raise ValueError(f"{entry.code}: expected {entry.words} registers, got {len(words)}")
    ordered = list(words) if entry.word_order == "low_first" else list(reversed(words))
    if entry.combine == "decimal":
        base = 10**entry.digits
        # Each word carries `digits` decimal digits; the top word keeps the sign when the drive sends one.
        top = ordered[-1] - 0x10000 if entry.signed and ordered[-1] & 0x8000 else ordered[-1]
        value = top
        for w in reversed(ordered[:-1]):
            value = value * base + (w if top >= 0 else -w)
        return value
    value = 0
    for i, w in enumerate(ordered):
        value |= (w & 0xFFFF) << (16 * i)
    bits = 16 * entry.words
    if entry.signed and value & (1 << (bits - 1)):
        value -= 1 << bits
    return value


def raw_to_words(entry: Entry, raw: int) -> list[int]:
    """Split a raw integer into the entry's registers in wire order."""
    if entry.combine == "decimal":
        base = 10**entry.digits
        sign = -1 if raw < 0 else 1
        rest = abs(raw)
        parts = []
        for _ in range(entry.words - 1):
            parts.append(rest % base)
            rest //= base
        parts.append((sign * rest) & 0xFFFF)
        parts = [p & 0xFFFF for p in parts]  # a 5-digit half can exceed 16 bits (the SDC manual's own puzzle)
        ordered = parts
    else:
        bits = 16 * entry.words
        value = raw & ((1 << bits) - 1)
        ordered = [(value >> (16 * i)) & 0xFFFF for i in range(entry.words)]
    return ordered if entry.word_order == "low_first" else list(reversed(ordered))


def raw_to_eng(entry: Entry, raw: int) -> float | int:
    """Engineering value of a raw integer (int when the scale is 1)."""
    if entry.scale == 1:
        return raw
    value = raw * entry.scale
    return round(value, decimals(entry))


def eng_to_raw(entry: Entry, eng: float, *, clamp: bool = True) -> int:
    """The raw integer nearest an engineering value; clamped into the entry's range unless clamp=False (then the
    caller checks the range itself). The one eng->raw conversion for computed values (user input: parse_value)."""
    raw = round(eng / entry.scale)
    return max(entry.min, min(entry.max, raw)) if clamp else raw


def as_held(entry: Entry, eng: float) -> float | int | None:
    """A computed value as the entry holds it: to its resolution, an int where the scale is 1 (-2, not -2.0; 300,
    not 300.0); None where it is not finite (JSON has no NaN)."""
    return raw_to_eng(entry, eng_to_raw(entry, eng, clamp=False)) if math.isfinite(eng) else None


def decimals(entry: Entry) -> int:
    """Digits after the point implied by the scale (0.1 -> 1, 0.01 -> 2)."""
    if entry.scale >= 1:
        return 0
    return max(0, math.ceil(-math.log10(entry.scale) - 1e-9))


def _digit_fields(entry: Entry, raw: int) -> list[int]:
    mask = (1 << entry.field_width) - 1
    return [(raw >> (entry.field_width * i)) & mask for i in range(len(entry.fields))]


def field_limit(entry: Entry) -> int:
    """Largest value a field can show on the panel: two decimal digits (two-param) or one digit (four-param)."""
    return 99 if entry.field_width == 8 else 15


def field_range(entry: Entry, name: str) -> tuple[int, int]:
    """(lo, hi) of a field: the profile's field_ranges, else everything the panel can show."""
    return entry.field_ranges.get(name.upper(), (0, field_limit(entry)))


def field_index(entry: Entry, name: str) -> int:
    """Position of a field (0 = lowest), case-insensitive; UsageError naming the valid fields."""
    names = [f.upper() for f in entry.fields]
    if entry.format != "digits":
        raise UsageError(
            f"{entry.code} ({entry.name}) has no fields: CODE.FIELD works only for two-/four-parameter (d/b) entries"
        )
    if name.strip().upper() not in names:
        raise UsageError(f"{entry.code}: unknown field '{name.strip()}' (fields: {', '.join(reversed(entry.fields))})")
    return names.index(name.strip().upper())


def split_field(profile: Profile, text: str) -> tuple[Entry, str | None]:
    """'Po001' -> (entry, None); 'Po001.Y' -> (entry, 'Y') for a digit entry; UsageError for a bad field."""
    text = text.strip()
    if profile.find(text) is not None or "." not in text:
        return profile.entry(text), None
    code, _, name = text.rpartition(".")
    if profile.find(code) is None:
        return profile.entry(text), None  # unknown as a whole ('H08.00' on a drive without H08-00)
    entry = profile.entry(code)
    return entry, entry.fields[field_index(entry, name)]


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


def fields_json(entry: Entry, raw: int) -> dict[str, int] | None:
    """{field: value}, highest field first, for a displayable digit value; None otherwise."""
    if entry.format != "digits" or not _displayable(entry, raw):
        return None
    return {f: v for f, v in reversed(list(zip(entry.fields, _digit_fields(entry, raw), strict=True)))}


def get_field(entry: Entry, raw: int, name: str) -> int:
    """Value of one field of a digit-encoded raw value."""
    return _digit_fields(entry, raw)[field_index(entry, name)]


def format_field(entry: Entry, raw: int, name: str) -> str:
    """Text of one field, with its meaning when the profile names it (e.g. '2 (ball screw / linear motor)')."""
    field = entry.fields[field_index(entry, name)]
    value = get_field(entry, raw, name)
    meaning = entry.field_enums.get(field.upper(), {}).get(value)
    return f"{value} ({meaning})" if meaning else str(value)


def _displayable(entry: Entry, raw: int) -> bool:
    """Whether a raw value is a valid panel display (fields within the panel's digits, nothing above them)."""
    vals = _digit_fields(entry, raw)
    return raw >> (entry.field_width * len(entry.fields)) == 0 and all(v <= field_limit(entry) for v in vals)


def format_value(entry: Entry, raw: int) -> str:
    """Text of a raw value in the form the manual shows."""
    if entry.format == "digits":
        if not _displayable(entry, raw):
            return f"0x{raw & 0xFFFF:04X}"  # not a panel value (a drive fault or a foreign write): show it exactly
        # Fields are listed from the lowest up; the panel shows the highest first, after its mode flag:
        # two-param 'd Y X' with blank leading zeros (the manual's 'd 1 21', example 5 'd_1_10'),
        # four-param 'b' and one digit per field ('b1200', example 6 'b1234').
        vals = list(reversed(_digit_fields(entry, raw)))
        if entry.field_width == 8:
            return "d " + " ".join(str(v) for v in vals)
        return "b" + "".join(f"{v:X}" for v in vals)
    if entry.format == "hex":
        return f"0x{raw & ((1 << (16 * entry.words)) - 1):0{4 * entry.words}X}"
    if entry.format == "bits":
        on = [name for bit, name in sorted(entry.bits.items()) if raw >> bit & 1]
        return f"0x{raw:04X}" + (f" [{' '.join(on)}]" if on else "")
    eng = raw_to_eng(entry, raw)
    text = f"{eng:.{decimals(entry)}f}" if isinstance(eng, float) else str(eng)
    if entry.enum and raw in entry.enum:
        text += f" ({entry.enum[raw]})"
    return text


def json_value(entry: Entry, raw: int) -> int | float:
    """Value for machine-readable output: always a number (the engineering value; for an encoded entry, two-/four-
    parameter digits, hex, a bit field, the register's value); json_text gives the manual's form beside it."""
    return raw_to_eng(entry, raw)


def json_text(entry: Entry, raw: int) -> str | None:
    """The manual's form of an encoded value ('d 1 21', 'b1200', '0x0003 [DI1 DI2]') for a `text` field beside the
    number; None for a plain number."""
    return format_value(entry, raw) if entry.format in ("digits", "hex", "bits") else None


def parse_value(entry: Entry, text: str, *, raw: bool = False, current: int | None = None) -> int:
    """Parse user input into a raw integer, checking type and range; raise UsageError with a clear message."""
    text = text.strip()
    what = f"{entry.code} ({entry.name})"
    if not text:
        raise UsageError(f"{what}: empty value")
    value = _parse_encoded(entry, text, current) if not raw else None
    if value is None and entry.enum and not raw:
        value = enum_value(entry.enum, text)
    if value is None:
        value = _parse_number(entry, _without_unit(entry, text) if not raw else text, raw=raw)
    lo, hi = entry.min, entry.max
    if not lo <= value <= hi:
        rng = f"{format_value(entry, lo)}..{format_value(entry, hi)}"
        raise UsageError(f"{what}: value {text} is out of range {rng}{' ' + entry.unit if entry.unit else ''}")
    if entry.enum and value not in entry.enum and entry.format == "dec":
        raise UsageError(f"{what}: {text} is not one of {_choices(entry)}")
    return value


def _without_unit(entry: Entry, text: str) -> str:
    """'3000rpm' -> '3000' for an entry in rpm; a unit that is not the entry's is refused, naming the right one."""
    number, unit = split_unit(text, entry.unit)
    if unit is None:
        return text
    if unit_matches(unit, entry.unit):
        return number
    what = f"{entry.code} ({entry.name})"
    if entry.enum:
        raise UsageError(f"{what}: '{text}' is none of {_choices(entry)}")
    if not entry.unit:
        raise UsageError(f"{what}: takes a plain number (no unit), not '{text}'")
    # A prefixed unit (3krpm) is another number in the entry's unit: no example made of the same digits.
    example = f"give it in {entry.unit}" if unit.lower().endswith(entry.unit.lower()) else f"e.g. {number}{entry.unit}"
    raise UsageError(f"{what}: '{text}' is in {unit}, but {entry.code} is in {entry.unit} ({example})")


def _choices(entry: Entry) -> str:
    return ", ".join(f"{k}={v}" for k, v in sorted(entry.enum.items()))


def _parse_number(entry: Entry, text: str, *, raw: bool) -> int:
    what = f"{entry.code} ({entry.name})"
    if not raw and entry.scale != 1 and re.fullmatch(r"[+-]?0[xXbB][0-9a-fA-F]+", text):
        # A hex/binary literal is a register pattern; read as engineering units it would be off by the scale.
        raise UsageError(
            f"{what}: {text} reads as a raw register value; give the value in "
            f"{entry.unit or 'units'} (resolution {entry.scale:g}) or use --raw"
        )
    if not text.isascii() or "_" in text:  # float() takes '٣', '５' and '1_0'; a drive value is plain digits
        raise UsageError(f"{what}: '{text}' is not a number (plain ASCII digits, e.g. 3 or 2.5)")
    try:
        if re.fullmatch(r"[+-]?0[xX][0-9a-fA-F]+", text):
            return int(text, 16)
        if re.fullmatch(r"[+-]?0[bB][01]+", text):
            return int(text, 2)
        number = float(text)
    except ValueError:
        if entry.enum and not raw:
            hint = did_you_mean(text, entry.enum.values())
            raise UsageError(f"{what}: '{text}' is none of {_choices(entry)}{hint}") from None
        raise UsageError(f"{what}: '{text}' is not a number") from None
    if not math.isfinite(number):
        raise UsageError(f"{what}: '{text}' is not a finite number")
    scaled = number if raw else number / entry.scale
    nearest = round(scaled)
    if abs(scaled - nearest) > 1e-6 * max(1.0, abs(scaled)):
        step = "1" if raw else f"{entry.scale:g}"
        raise UsageError(f"{what}: {text} is not a multiple of the resolution {step}")
    return int(nearest)


_FLAG_RE = re.compile(r"^([dDbB])(?=[\s_0-9A-Fa-f]|$)[\s_]*")


def _parse_encoded(entry: Entry, text: str, current: int | None) -> int | None:
    """Digit-field input, None when the text is not in a digit form (then it is read as a plain number).

    Forms: the manual's 'd 1 21' / 'd1 21' / 'd_1_21' (two-param) and 'b1200' / 'b 1 2 0 0' (four-param), the
    bare fields '1 21' / '01 21' / '1200' / '1 2 0 0' (older servotool output), and 'X=21' / 'Y=1,X=21' (some
    fields, the rest kept from `current`).
    """
    if entry.format != "digits":
        return None
    width = entry.field_width
    n = len(entry.fields)
    flag = "d" if width == 8 else "b"
    example = format_value(entry, entry.default or 0)
    parts = [p for p in re.split(r"[\s,]+", text) if p]
    if parts and all("=" in p for p in parts):
        vals = _digit_fields(entry, current if current is not None else entry.default or 0)
        for part in parts:
            name, _, val = part.partition("=")
            idx = field_index(entry, name)
            vals[idx] = _field_int(entry, idx, val)
        return _pack(entry, vals)
    m = _FLAG_RE.match(text)
    if m and not text.lower().startswith(("0x", "0b")):
        if m.group(1).lower() != flag:
            kind = "two-parameter (d Y X)" if width == 8 else "four-parameter (b D C B A)"
            raise UsageError(f"{entry.code}: '{text}' has the wrong mode flag: it is a {kind} value, e.g. {example}")
        body = [p for p in re.split(r"[\s_,]+", text[m.end() :]) if p]
        if width == 4 and len(body) == 1 and len(body[0]) == n:
            body = list(body[0])
        if len(body) != n:
            raise UsageError(
                f"{entry.code}: '{text}' needs {n} fields ({' '.join(reversed(entry.fields))}), e.g. {example}"
            )
        return _pack(entry, [_field_int(entry, i, p) for i, p in enumerate(reversed(body))])
    if len(parts) == n and n > 1:
        return _pack(entry, [_field_int(entry, i, p) for i, p in enumerate(reversed(parts))])
    if (
        width == 4
        and len(parts) == 1
        and len(parts[0]) == n
        and parts[0].isalnum()
        and not parts[0].lower().startswith("0x")
    ):
        return _pack(entry, [_field_int(entry, i, c) for i, c in enumerate(reversed(parts[0]))])
    return None


def _pack(entry: Entry, vals: list[int]) -> int:
    return sum(v << (entry.field_width * i) for i, v in enumerate(vals))


def _field_int(entry: Entry, idx: int, text: str) -> int:
    """One field's value (index from the lowest), checked against the panel's digits and the field's range."""
    name = entry.fields[idx]
    text = text.strip()
    try:
        # A four-param digit may be a hex letter on the panel; a two-param field is two decimal digits.
        plain = text.isascii() and text.isdigit()
        v = int(text) if plain else (int(text, 16) if entry.field_width == 4 and len(text) == 1 else None)
    except ValueError:
        v = None
    meanings = entry.field_enums.get(name.upper(), {})
    if v is None and meanings:  # a field's meaning by name, as for a whole entry (Po001.X=bus)
        v = enum_value(meanings, text)
        if v is None:
            choices = ", ".join(f"{k}={m}" for k, m in sorted(meanings.items()))
            raise UsageError(
                f"{entry.code}: field {name} value '{text}' is none of {choices}{did_you_mean(text, meanings.values())}"
            )
    if v is None:
        raise UsageError(f"{entry.code}: field {name} value '{text}' is not a digit")
    lo, hi = field_range(entry, name)
    if not lo <= v <= hi:
        raise UsageError(f"{entry.code}: field {name}={v} is out of range {lo}..{hi}")
    return v
