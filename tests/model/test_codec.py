"""Value conversion: signed values, 32/64-bit in both word orders, decimal word pairs, scaling, digit fields."""

from __future__ import annotations

import pytest

from servotool.errors import UsageError
from servotool.model.codec import (
    format_field,
    format_value,
    parse_value,
    raw_to_eng,
    raw_to_words,
    split_field,
    words_to_raw,
)
from servotool.model.loader import load_profile
from servotool.model.profile import Entry


def entry(**kw) -> Entry:
    base = {"code": "X1", "cls": "Pn", "name": "test", "address": 0, "min": -(2**31), "max": 2**31 - 1}
    base.update(kw)
    if "type" in kw and kw["type"] in ("u16",):
        base.setdefault("min", 0)
    return Entry(**base)


@pytest.mark.parametrize(
    ("typ", "order", "raw", "words"),
    [
        ("s16", "low_first", -1, [0xFFFF]),
        ("s16", "low_first", -32768, [0x8000]),
        ("u16", "low_first", 65535, [0xFFFF]),
        ("s32", "low_first", -99999, [0x7961, 0xFFFE]),  # SD25 manual example 7: hi 65534, lo 31073
        ("s32", "high_first", -99999, [0xFFFE, 0x7961]),
        ("u32", "low_first", 8388608, [0x0000, 0x0080]),
        ("u32", "high_first", 0x12345678, [0x1234, 0x5678]),
        ("s64", "low_first", -2, [0xFFFE, 0xFFFF, 0xFFFF, 0xFFFF]),
    ],
)
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
    with pytest.raises(UsageError, match="raw register value"):
        parse_value(e, "0x10")  # 16 raw or 16 1/s? refused, not guessed
    assert parse_value(e, "0x10", raw=True) == 16


def test_signed_parse_and_hex():
    e = entry(type="s16", min=-1000, max=1000)
    assert parse_value(e, "-1000") == -1000
    assert parse_value(e, "0x10") == 16
    with pytest.raises(UsageError):
        parse_value(e, "-1001")


def two_param(**kw) -> Entry:
    base = {
        "type": "u16",
        "min": 0,
        "max": 0xFFFF,
        "format": "digits",
        "fields": ("X", "Y"),
        "field_width": 8,
        "default": 0x0101,
    }
    return entry(**{**base, **kw})


def four_param(**kw) -> Entry:
    base = {
        "type": "u16",
        "min": 0,
        "max": 0xFFFF,
        "format": "digits",
        "fields": ("A", "B", "C", "D"),
        "field_width": 4,
        "default": 0,
    }
    return entry(**{**base, **kw})


def test_two_parameter_value_is_shown_and_read_as_the_manual_prints_it():
    e = two_param()
    assert format_value(e, 266) == "d 1 10"  # manual example 5: d_1_10 = 0x010A, reads 266
    assert format_value(e, 0x0115) == "d 1 21"  # Po001 factory 'd 1 21'
    assert format_value(e, 0x0101) == "d 1 1"  # Po505 factory, printed 'd 11' (blanks lost)
    assert format_value(e, 0x0000) == "d 0 0"  # So-58 factory 'd 0 0'
    for text in ("d 1 10", "d1 10", "d_1_10", "D 1 10", "d 1_10", "1 10", "01 10", "X=10,Y=1", "266", "0x010A"):
        assert parse_value(e, text) == 266, text
    assert parse_value(e, "d1 34") == 0x0122  # Po413 as printed in section 7.10.8


def test_four_parameter_value_is_shown_and_read_as_the_manual_prints_it():
    e = four_param()
    assert format_value(e, 0x1234) == "b1234"  # manual example 6: write 0x1234, panel shows b1234
    assert format_value(e, 0x1200) == "b1200"  # Po175 factory
    for text in ("b1234", "B1234", "b 1 2 3 4", "b_1_2_3_4", "1234", "1 2 3 4", "D=1,C=2,B=3,A=4", "0x1234"):
        assert parse_value(e, text) == 0x1234, text


def test_field_assignment_changes_only_that_field_of_the_current_value():
    e = two_param()
    assert parse_value(e, "X=0", current=0x0101) == 0x0100
    assert parse_value(e, "x=7", current=0x0105) == 0x0107  # field names are case-insensitive
    assert parse_value(e, "Y=2,X=3") == 0x0203
    assert parse_value(four_param(), "C=3", current=0x1211) == 0x1311


@pytest.mark.parametrize(
    ("make", "text", "message"),
    [
        (two_param, "Z=1", r"unknown field 'Z' \(fields: Y, X\)"),
        (two_param, "X=100", r"field X=100 is out of range 0\.\.99"),
        (two_param, "d 1", r"'d 1' needs 2 fields \(Y X\), e\.g\. d 1 1"),
        (two_param, "d 11", r"needs 2 fields"),  # ambiguous without the panel's blanks
        (two_param, "b1234", r"wrong mode flag: it is a two-parameter \(d Y X\) value"),
        (two_param, "d 1 x", r"field X value 'x' is not a digit"),
        (four_param, "b123", r"needs 4 fields \(D C B A\)"),
        (four_param, "d 1 2", r"wrong mode flag: it is a four-parameter"),
        (four_param, "A=16", r"field A=16 is out of range 0\.\.15"),
    ],
)
def test_malformed_digit_input_is_a_one_line_error(make, text, message):
    with pytest.raises(UsageError, match=message) as info:
        parse_value(make(), text)
    assert "\n" not in str(info.value)


def test_field_ranges_from_the_profile_are_enforced_and_named():
    e = four_param(field_ranges={"C": (1, 3), "D": (1, 3)}, min=0x1100, max=0x3311, default=0x1200)
    assert parse_value(e, "b3300") == 0x3300
    with pytest.raises(UsageError, match=r"field C=4 is out of range 1\.\.3"):
        parse_value(e, "C=4", current=0x1200)
    with pytest.raises(UsageError, match=r"field D=0 is out of range 1\.\.3"):
        parse_value(e, "b0200")


def test_a_value_the_panel_cannot_show_is_printed_exactly_and_reads_back():
    e = two_param()
    assert format_value(e, 0xFFFF) == "0xFFFF"  # 255 in a two-digit field: not a panel value
    assert parse_value(e, format_value(e, 0xFFFF)) == 0xFFFF


def test_sd25_digit_entries_carry_the_manuals_field_ranges():
    p = load_profile("sd25")
    assert p.entry("Po001").field_ranges == {"X": (0, 21), "Y": (0, 1)}
    assert p.entry("Po175").field_ranges == {"A": (0, 1), "B": (0, 1), "C": (1, 3), "D": (1, 3)}
    assert p.entry("Po505").field_enums["X"][1] == "writes kept in RAM only"
    assert "D" not in p.entry("So-66").field_ranges  # not described in the manual: unrestricted
    e = p.entry("Po175")
    assert format_field(e, 0x1200, "c") == "2 (ball screw or linear motor)"
    assert split_field(p, "Po175.c") == (e, "C")
    assert split_field(p, "po175") == (e, None)
    with pytest.raises(UsageError, match=r"Po109 .* has no fields"):
        split_field(p, "Po109.X")


def test_enum_by_name():
    e = entry(type="u16", min=0, max=2, enum={0: "position", 1: "speed", 2: "torque"})
    assert parse_value(e, "speed") == 1
    assert format_value(e, 2) == "2 (torque)"


def test_backups_with_the_old_display_forms_still_diff_and_restore(cli, tmp_path):
    """Backups written before the manual's forms carry '00 05' / '2 3 1 1' in their display section."""
    f = tmp_path / "old.yaml"
    sim = ("--profile", "sd25", "--port", "sim")
    assert cli(*sim, "param", "set", "--save", "Po001=d 0 5", "Po175=b2311").code == 0
    assert cli(*sim, "param", "backup", "-o", str(f)).code == 0
    text = f.read_text()
    assert "Po001: d 0 5\n" in text and "Po175: b2311\n" in text
    f.write_text(text.replace("Po001: d 0 5\n", "Po001: 00 05\n").replace("Po175: b2311\n", "Po175: 2 3 1 1\n"))
    assert cli(*sim, "param", "set", "--save", "Po001.X=21", "Po175.C=2").code == 0
    r = cli(*sim, "param", "diff", str(f), "--json")
    assert r.code in (0, 1), r.err
    assert "d 0 5" in r.out and "b2311" in r.out and "d 0 21" in r.out and "b2211" in r.out
    r = cli(*sim, "param", "restore", str(f), "--yes")
    assert r.code == 0, r.err
    r = cli(*sim, "param", "get", "Po001", "Po175", "--json")
    assert [(v["value"], v["text"]) for v in r.json()] == [(5, "d 0 5"), (0x2311, "b2311")]
