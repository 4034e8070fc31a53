"""Finding what the user means: code spellings, groups, units, enum names, suggestions."""

from __future__ import annotations

import pytest

from servotool.errors import UnknownName, UsageError
from servotool.model import lookup
from servotool.model.codec import parse_value, split_field
from servotool.model.loader import load_profile
from servotool.ops.params import select


@pytest.mark.parametrize(
    ("profile", "typed", "code"),
    [
        ("is620p", "H08.00", "H08-00"),
        ("is620p", "H0800", "H08-00"),
        ("is620p", "h0c-09", "H0C-09"),
        ("dsx7e", "Pn4", "Pn004"),
        ("dsx7e", "PN004", "Pn004"),
        ("sdc", "PN017", "PN17"),
        ("sd25", "So58", "So-58"),
    ],
)
def test_the_manuals_other_spellings_find_the_entry(profile, typed, code):
    assert load_profile(profile).entry(typed).code == code


def test_a_spelling_two_entries_share_is_refused_naming_both():
    p = load_profile("dsx7e")
    p._aliases()["PN4"] = [p.entry("Pn004"), p.entry("Pn100")]  # as if two codes had the same key
    try:
        with pytest.raises(UnknownName) as caught:
            p.entry("Pn4")
        assert caught.value.suggestions == ["Pn004", "Pn100"]
    finally:
        del p.__dict__["_alias_index"]


def test_unknown_code_suggests_close_ones_and_a_field_is_still_a_field():
    p = load_profile("dsx7e")
    with pytest.raises(UnknownName, match=r"did you mean Pn101"):
        p.entry("Pn1O1")
    with pytest.raises(UnknownName, match=r"unknown code 'H08.00'"):
        split_field(p, "H08.00")
    assert split_field(load_profile("sd25"), "Po001.Y")[1] == "Y"


def test_groups_any_case_and_common_names_on_every_profile():
    for pid in ("dsx7e", "sd25", "is620p", "sdc"):
        p = load_profile(pid)
        for name in ("gain", "speed", "position", "torque", "io", "comm", "monitor"):
            entries = select(p, group=name.upper(), classes=("Pn", "Un", "Sn"))
            assert entries, (pid, name)
    assert {e.group for e in select(load_profile("is620p"), group="gain")} == {"H08", "H09"}
    with pytest.raises(UnknownName, match="did you mean speed"):
        select(load_profile("dsx7e"), group="sped")


@pytest.mark.parametrize(
    ("code", "typed", "raw"),
    [
        ("Pn027", "3000rpm", 3000),
        ("Pn027", "3000 r/min", 3000),
        ("Pn101", "25Hz", 250),
        ("Pn101", "25", 250),
        ("Pn004", "300%", 300),
    ],
)
def test_a_value_with_its_unit(code, typed, raw):
    assert parse_value(load_profile("dsx7e").entry(code), typed) == raw


def test_numbers_with_an_exponent_or_in_hex_are_no_units():
    assert lookup.split_unit("1e-300", "rpm") == ("1e-300", None)
    assert lookup.split_unit("0x1F", "") == ("0x1F", None)
    assert lookup.split_unit("3000 r/min", "rpm") == ("3000", "r/min")


def test_a_value_in_another_unit_is_refused_naming_the_right_one():
    entry = load_profile("dsx7e").entry("Pn027")
    with pytest.raises(UsageError, match=r"'3000Hz' is in Hz, but Pn027 is in rpm \(e.g. 3000rpm\)"):
        parse_value(entry, "3000Hz")
    with pytest.raises(UsageError, match=r"'3krpm' is in krpm, but Pn027 is in rpm \(give it in rpm\)"):
        parse_value(entry, "3krpm")  # not 'e.g. 3rpm'


def test_enum_names_whole_or_a_unique_start_and_typos_get_suggestions():
    entry = load_profile("sdc").entry("PN4")
    assert parse_value(entry, "jog") == 3 and parse_value(entry, "ENCODER") == 4
    with pytest.raises(UsageError, match=r"is none of .*3=jog"):
        parse_value(entry, "jgo")
    assert lookup.enum_value({0: "speed mode", 1: "speed trial"}, "speed") is None  # ambiguous


def test_did_you_mean_wording():
    assert lookup.did_you_mean("gian", ["gain", "io"]) == "; did you mean gain?"
    assert lookup.did_you_mean("zzz", ["gain"]) == ""
