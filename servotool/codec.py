"""Value conversion: registers <-> raw integers <-> engineering values and text."""

from __future__ import annotations

import math
import re

from servotool.errors import UsageError
from servotool.profile import Entry


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


def decimals(entry: Entry) -> int:
    """Digits after the point implied by the scale (0.1 -> 1, 0.01 -> 2)."""
    if entry.scale >= 1:
        return 0
    return max(0, math.ceil(-math.log10(entry.scale) - 1e-9))


def _digit_fields(entry: Entry, raw: int) -> list[int]:
    mask = (1 << entry.field_width) - 1
    return [(raw >> (entry.field_width * i)) & mask for i in range(len(entry.fields))]


def format_value(entry: Entry, raw: int) -> str:
    """Text of a raw value in the form the manual shows."""
    if entry.format == "digits":
        vals = _digit_fields(entry, raw)
        width = 2 if entry.field_width == 8 else 1
        # Fields are listed from the lowest up; the panel shows the highest first.
        return " ".join(f"{v:0{width}d}" if entry.field_width == 8 else f"{v:X}" for v in reversed(vals))
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


def json_value(entry: Entry, raw: int) -> int | float | str:
    """Value for machine-readable output: engineering number, or the manual's text for encoded formats."""
    if entry.format in ("digits", "hex"):
        return format_value(entry, raw)
    return raw_to_eng(entry, raw)


_FIELD_RE = re.compile(r"^[A-Za-z]$")


def parse_value(entry: Entry, text: str, *, raw: bool = False, current: int | None = None) -> int:
    """Parse user input into a raw integer, checking type and range; raise UsageError with a clear message."""
    text = text.strip()
    what = f"{entry.code} ({entry.name})"
    if not text:
        raise UsageError(f"{what}: empty value")
    value = _parse_encoded(entry, text, current) if not raw else None
    if value is None:
        if entry.enum:
            by_name = {v.lower(): k for k, v in entry.enum.items()}
            if text.lower() in by_name:
                value = by_name[text.lower()]
        if value is None:
            value = _parse_number(entry, text, raw=raw)
    lo, hi = entry.min, entry.max
    if not lo <= value <= hi:
        rng = f"{format_value(entry, lo)}..{format_value(entry, hi)}"
        raise UsageError(f"{what}: value {text} is out of range {rng}{' ' + entry.unit if entry.unit else ''}")
    if entry.enum and value not in entry.enum and entry.format == "dec":
        choices = ", ".join(f"{k}={v}" for k, v in sorted(entry.enum.items()))
        raise UsageError(f"{what}: {text} is not one of {choices}")
    return value


def _parse_number(entry: Entry, text: str, *, raw: bool) -> int:
    what = f"{entry.code} ({entry.name})"
    try:
        if re.fullmatch(r"[+-]?0[xX][0-9a-fA-F]+", text):
            return int(text, 16)
        if re.fullmatch(r"[+-]?0[bB][01]+", text):
            return int(text, 2)
        number = float(text)
    except ValueError:
        raise UsageError(f"{what}: '{text}' is not a number") from None
    if not math.isfinite(number):
        raise UsageError(f"{what}: '{text}' is not a finite number")
    scaled = number if raw else number / entry.scale
    nearest = round(scaled)
    if abs(scaled - nearest) > 1e-6 * max(1.0, abs(scaled)):
        step = "1" if raw else f"{entry.scale:g}"
        raise UsageError(f"{what}: {text} is not a multiple of the resolution {step}")
    return int(nearest)


def _parse_encoded(entry: Entry, text: str, current: int | None) -> int | None:
    """Digit-field input: '1 21' (all fields, highest first) or 'X=21' / 'Y=1,X=21' (some fields)."""
    if entry.format != "digits":
        return None
    width = entry.field_width
    limit = 99 if width == 8 else 15
    names = [f.upper() for f in entry.fields]
    parts = [p for p in re.split(r"[\s,]+", text) if p]
    if parts and all("=" in p for p in parts):
        vals = _digit_fields(entry, current if current is not None else entry.default or 0)
        for part in parts:
            name, _, val = part.partition("=")
            if name.upper() not in names:
                raise UsageError(f"{entry.code}: unknown field '{name}' (fields: {', '.join(reversed(entry.fields))})")
            vals[names.index(name.upper())] = _field_int(entry, val, limit)
    elif len(parts) == len(names) and len(parts) > 1:
        vals = [_field_int(entry, p, limit) for p in reversed(parts)]
    elif width == 4 and len(parts) == 1 and len(parts[0]) == len(names) and parts[0].isalnum() \
            and not parts[0].lower().startswith("0x"):
        vals = [_field_int(entry, c, limit) for c in reversed(parts[0])]
    else:
        return None
    return sum(v << (width * i) for i, v in enumerate(vals))


def _field_int(entry: Entry, text: str, limit: int) -> int:
    try:
        v = int(text, 16) if entry.field_width == 4 else int(text)
    except ValueError:
        raise UsageError(f"{entry.code}: field value '{text}' is not a digit") from None
    if not 0 <= v <= limit:
        raise UsageError(f"{entry.code}: field value {text} is outside 0..{limit}")
    return v
