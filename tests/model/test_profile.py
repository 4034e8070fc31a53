"""Profile schema: good files load, broken files report each problem with its location."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from servotool.errors import ProfileError
from servotool.model.loader import builtin_ids, load_profile, read_profile
from servotool.model.schema import parse_profile

GOOD = {
    "schema": 1,
    "id": "mini",
    "model": "MINI",
    "vendor": "test",
    "version": "1",
    "description": "test drive",
    "source": "test",
    "address_rule": "address = n",
    "serial": {"baud": 9600, "parity": "N", "stopbits": 1, "bytesize": 8, "unit": 1},
    "limits": {"max_read": 10, "max_write": 10},
    "word_order": "low_first",
    "persistence": {"mode": "immediate"},
    "roles": {"speed_feedback": "U1"},
    "entries": [
        {
            "code": "P1",
            "class": "Pn",
            "name": "gain",
            "address": 1,
            "min": 0,
            "max": 100,
            "default": 10,
            "effect": "immediate",
            "source": "t",
        },
        {
            "code": "P2",
            "class": "Pn",
            "name": "big",
            "address": 2,
            "type": "s32",
            "min": -100000,
            "max": 100000,
            "default": 0,
            "effect": "power_cycle",
            "source": "t",
        },
        {"code": "U1", "class": "Un", "name": "speed", "address": 100, "type": "s16", "source": "t"},
    ],
}


def write(tmp_path: Path, data: dict, name: str = "mini") -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_good_profile_loads(tmp_path):
    profile = load_profile(write(tmp_path, GOOD))
    assert [e.code for e in profile.entries] == ["P1", "P2", "U1"]
    assert profile.entry("p2").words == 2
    assert profile.role("speed_feedback").code == "U1"
    assert profile.entry("speed_feedback").code == "U1"


@pytest.mark.parametrize(
    ("mutate", "expected"),
    [
        (lambda d: d["entries"][0].update(default=200), "entries[0] (P1).default: 200 outside min..max 0..100"),
        (lambda d: d["entries"][1].update(address=1), "address 1 (0x0001) overlaps P1"),
        (lambda d: d["entries"][2].update(code="p1"), "duplicate code"),
        (lambda d: d["entries"][0].update(type="u17"), '"u17" is not one of'),
        (lambda d: d["entries"][0].pop("effect"), "Pn entry needs 'effect'"),
        (lambda d: d["entries"][0].update(min=-5), "entries[0] (P1).min: -5 is outside 0..65535 (the u16 range)"),
        (lambda d: d["roles"].update(jog="F9"), 'roles.jog: names unknown entry "F9"'),
        (lambda d: d.update(word_order="middle"), 'word_order: "middle" is not one of'),
        (lambda d: d["limits"].update(max_read=500), "limits.max_read: 500 is outside 1..125"),
        (lambda d: d["entries"][0].update(colour="red"), "unknown key 'colour'"),
        (lambda d: d["entries"][0].update(format="digits"), "format: digits needs 'fields'"),
        (lambda d: d.pop("model"), "missing required key 'model'"),
        (
            lambda d: d.update(motion_setup=[{"code": "P9", "value": 1, "reason": "r", "source": "s"}]),
            'motion_setup[0] (P9).code: names unknown entry "P9"',
        ),
        (
            lambda d: d.update(motion_setup=[{"code": "U1", "value": 1, "reason": "r", "source": "s"}]),
            "motion_setup[0] (U1).code: U1 is not a settable parameter",
        ),
        (
            lambda d: d.update(motion_setup=[{"code": "P1", "value": 101, "reason": "r", "source": "s"}]),
            "motion_setup[0] (P1).value: P1 (gain): value 101 is out of range 0..100",
        ),
        (
            lambda d: d.update(motion_setup=[{"code": "P1", "value": "X=1", "reason": "r", "source": "s"}]),
            "motion_setup[0] (P1).value: P1 (gain): 'X=1' is not a number",
        ),
        (
            lambda d: d.update(motion_setup=[{"code": "P1", "value": 1, "source": "s"}]),
            "motion_setup[0]: missing required key 'reason'",
        ),
        (
            lambda d: d.update(motion_setup=[{"code": "P1", "value": 1, "reason": "r", "source": "s", "when": "x"}]),
            "motion_setup[0]: unknown key 'when'",
        ),
    ],
)
def test_broken_profile_reports_location(tmp_path, mutate, expected):
    import copy

    data = copy.deepcopy(GOOD)
    mutate(data)
    profile, problems = read_profile(write(tmp_path, data))
    assert profile is None
    assert any(expected in p for p in problems), problems
    assert all(p.startswith(str(tmp_path)) for p in problems)
    with pytest.raises(ProfileError, match="broken profile"):
        load_profile(tmp_path / "mini.yaml")


def test_all_problems_are_reported_not_just_the_first(tmp_path):
    import copy

    data = copy.deepcopy(GOOD)
    data["entries"][0]["default"] = 999
    data["entries"][2]["address"] = 2
    _, problems = read_profile(write(tmp_path, data))
    assert len(problems) >= 2


def test_locations_count_broken_entries_and_references_to_them_are_not_blamed_too(tmp_path):
    import copy

    data = copy.deepcopy(GOOD)
    data["entries"][0]["default"] = "ten"  # P1 broken
    data["entries"][2]["address"] = 2  # U1 (entries[2]) overlaps P2
    data["roles"]["inertia_ratio"] = "P1"
    _, problems = read_profile(write(tmp_path, data))
    assert len(problems) == 2, problems  # P1's own problem, and the overlap; the role naming P1 adds none
    assert any('entries[0] (P1).default: expected an integer, got "ten"' in p for p in problems), problems
    assert any("entries[2] (U1): address 2 (0x0002) overlaps P2" in p for p in problems), problems


def test_invalid_yaml_names_the_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("schema: 1\nentries: [\n  {code: P1\n")
    profile, problems = read_profile(path)
    assert profile is None and "invalid YAML" in problems[0] and "line" in problems[0]


def test_unknown_profile_is_a_clear_error():
    with pytest.raises(ProfileError, match="unknown profile 'nosuch'"):
        load_profile("nosuch")


def test_builtin_profiles_are_valid():
    assert "dsx7e" in builtin_ids()
    for pid in builtin_ids():
        profile, problems = read_profile(load_profile(pid).path)
        assert problems == [] and profile is not None


def test_dsx7e_addresses_follow_the_documented_rule():
    p = load_profile("dsx7e")
    for e in p.of_class("Pn"):
        n = int(e.code[2:])
        if e.source.startswith("DSX7E manual"):
            assert e.address == 0x2000 + 0x100 * (n // 100) + n % 100, e.code
    assert p.entry("Pn410").address == 0x240A  # the manual misprints 2410h
    assert p.entry("Un027").address == 0x401B
    assert p.entry("Pn008").words == 2


def test_inertia_ratio_convention_roundtrip():
    p = load_profile("dsx7e")
    assert p.load_ratio_from_param(250) == pytest.approx(1.5)
    assert p.param_from_load_ratio(0.0) == pytest.approx(100)


def test_motion_setup_values_read_as_users_type_them():
    """Built-in motion_setup values parse like `param set` input; a field assignment compares only its fields."""
    from servotool.model.setup import requirements

    reqs = {p: {r.entry.code: r for r in requirements(load_profile(p))} for p in builtin_ids()}
    assert reqs["dsx7e"] == {}
    assert {c: r.wanted for c, r in reqs["is620p"].items()} == {
        "H02-00": 1,
        "H05-00": 2,
        "H05-02": 10000,
        "H11-00": 0,
        "H11-01": 1,
        "H11-04": 0,
        "H0C-09": 1,
        "H17-00": 1,
        "H17-02": 28,
    }
    assert {c: r.wanted for c, r in reqs["sdc"].items()} == {"PN4": 3}
    po407 = reqs["sd25"]["Po407"]
    assert po407.fields == ("X",) and po407.met(0x011A) and po407.met(26) and not po407.met(0x1B)
    assert po407.assignments() == ["Po407.X=26"]
    assert "So-58" not in reqs["sd25"]  # servotool forces the DIs itself for a motion (forced_inputs)
    forced = load_profile("sd25").forced_inputs
    assert forced is not None and forced.switch_code == "So-58" and forced.levels_code == "So-57"
    assert forced.monitor_shows == "forced" and "which digit" in forced.unverified  # the digit meaning is a figure


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ({"field_ranges": {"Q": [0, 1]}}, "unknown field"),
        ({"field_ranges": {"X": [0, 100]}}, r"0 <= lo <= hi <= 99"),
        ({"field_ranges": {"X": [5, 9]}}, r"field X=1 is outside field_ranges.X 5\.\.9"),
        ({"field_ranges": {"Y": [0, 1]}, "max": 0x00FF, "default": 0x0001}, "exclude field values"),
        ({"format": "dec", "field_ranges": {"X": [0, 1]}}, "field_ranges need format: digits"),
    ],
)
def test_profile_checker_rejects_bad_field_ranges(extra, message):
    raw = {
        "code": "Po999",
        "class": "Pn",
        "name": "t",
        "address": 999,
        "min": 0,
        "max": 0xFFFF,
        "default": 0x0101,
        "effect": "immediate",
        "source": "test",
        "format": "digits",
        "fields": ["X", "Y"],
        "field_width": 8,
    }
    raw.update(extra)
    profile, problems = parse_profile({**GOOD, "entries": [*GOOD["entries"], raw]}, "t")
    assert profile is None
    assert any(re.search(message, p) and "Po999" in p for p in problems), problems
