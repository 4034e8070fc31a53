"""Value conversion: signed values, 32/64-bit in both word orders, decimal word pairs, scaling, digit fields."""

from __future__ import annotations

import pytest

from servotool.codec import format_value, parse_value, raw_to_eng, raw_to_words, words_to_raw
from servotool.errors import UsageError
from servotool.profile import Entry


def entry(**kw) -> Entry:
    base = {"code": "X1", "cls": "Pn", "name": "test", "address": 0, "min": -(2**31), "max": 2**31 - 1}
    base.update(kw)
    if "type" in kw and kw["type"] in ("u16",):
        base.setdefault("min", 0)
    return Entry(**base)


@pytest.mark.parametrize(("typ", "order", "raw", "words"), [
    ("s16", "low_first", -1, [0xFFFF]),
    ("s16", "low_first", -32768, [0x8000]),
    ("u16", "low_first", 65535, [0xFFFF]),
    ("s32", "low_first", -99999, [0x7961, 0xFFFE]),   # SD25 manual example 7: hi 65534, lo 31073
    ("s32", "high_first", -99999, [0xFFFE, 0x7961]),
    ("u32", "low_first", 8388608, [0x0000, 0x0080]),
    ("u32", "high_first", 0x12345678, [0x1234, 0x5678]),
    ("s64", "low_first", -2, [0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF]),
])
def test_words_roundtrip(typ, order, raw, words):
    e = entry(type=typ, word_order=order, min=-(2**63), max=2**64 - 1)
    assert raw_to_words(e, raw) == words
    assert words_to_raw(e, words) == raw


def test_decimal_word_pair():
    e = entry(type="s32", combine="decimal", digits=5, word_order="low_first")
    assert raw_to_words(e, 1234567) == [34567, 12]
    assert words_to_raw(e, [34567, 12]) == 1234567
    assert words_to_raw(e, raw_to_words(e, -1234567)) == -1234567


def test_scaling_and_parse():
    e = entry(type="u16", min=10, max=20000, scale=0.1, unit="1/s")
    assert raw_to_eng(e, 320) == 32.0
    assert format_value(e, 320) == "32.0"
    assert parse_value(e, "32.5") == 325
    assert parse_value(e, "40") == 400
    assert parse_value(e, "325", raw=True) == 325
    with pytest.raises(UsageError, match=r"out of range 1\.0\.\.2000\.0 1/s"):
        parse_value(e, "2000.1")
    with pytest.raises(UsageError, match=r"not a multiple of the resolution 0\.1"):
        parse_value(e, "32.55")
    with pytest.raises(UsageError, match="is not a number"):
        parse_value(e, "fast")
    with pytest.raises(UsageError, match="not a finite number"):
        parse_value(e, "nan")


def test_signed_parse_and_hex():
    e = entry(type="s16", min=-1000, max=1000)
    assert parse_value(e, "-1000") == -1000
    assert parse_value(e, "0x10") == 16
    with pytest.raises(UsageError):
        parse_value(e, "-1001")


def test_two_parameter_digits_like_sd25():
    e = entry(type="u16", min=0, max=0xFFFF, format="digits", fields=("X", "Y"), field_width=8, default=0x0101)
    assert format_value(e, 266) == "01 10"          # manual example 5: d 1 10 = 0x010A = 266
    assert parse_value(e, "1 10") == 266
    assert parse_value(e, "X=0", current=0x0101) == 0x0100
    assert parse_value(e, "Y=2,X=3") == 0x0203
    with pytest.raises(UsageError, match="unknown field"):
        parse_value(e, "Z=1")
    with pytest.raises(UsageError, match=r"outside 0\.\.99"):
        parse_value(e, "X=100")


def test_four_parameter_nibbles():
    e = entry(type="u16", min=0, max=0xFFFF, format="digits", fields=("A", "B", "C", "D"), field_width=4)
    assert format_value(e, 0x1234) == "1 2 3 4"
    assert parse_value(e, "1234") == 0x1234
    assert parse_value(e, "1 2 3 4") == 0x1234


def test_enum_by_name():
    e = entry(type="u16", min=0, max=2, enum={0: "position", 1: "speed", 2: "torque"})
    assert parse_value(e, "speed") == 1
    assert format_value(e, 2) == "2 (torque)"
