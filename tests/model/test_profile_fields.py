"""Every field of profiles/SCHEMA.md typed and checked: a shipped profile with one field broken is refused with one
line that names the file, the entry (or section) and the field (issue 30 item 8)."""

from __future__ import annotations

import copy
import math
from functools import cache
from pathlib import Path
from typing import Any

import pytest
import yaml

from servotool.model.loader import builtin_dir
from servotool.model.schema import parse_profile

DELETE = object()  # the mutation that removes the key


@cache
def shipped(pid: str) -> dict[str, Any]:
    return yaml.safe_load((builtin_dir() / f"{pid}.yaml").read_text(encoding="utf-8"))


# (profile, dotted path from the top, bad values): lists by index ("alarms.0.code").
FIELDS: list[tuple[str, str, list[Any]]] = [
    ("sd25", "schema", [None, 2, "1", True, DELETE]),
    ("sdc", "entries", [None, [], {"code": "PN1"}, DELETE]),
    ("sd25", "id", [None, "SD25", 25, "", DELETE]),
    *(("sd25", key, [None, "", 1.0, ["x"], DELETE]) for key in ("model", "vendor", "version", "description")),
    *(("sd25", key, [None, "", 5, DELETE]) for key in ("source", "address_rule")),
    ("sd25", "word_order", [None, "middle", DELETE]),
    ("sd25", "serial", [None, [], "9600 8N1", DELETE]),
    ("sd25", "serial.baud", [None, 0, "9600", 9600.5, True, DELETE]),
    ("sd25", "serial.parity", [None, "X", "n", 0, DELETE]),
    ("sd25", "serial.stopbits", [None, 3, 0, "1", DELETE]),
    ("sd25", "serial.bytesize", [None, 9, 6, "8", DELETE]),
    ("sd25", "serial.unit", [0, 248, -1, None, "1", 1.0, True, DELETE]),
    ("sd25", "limits", [None, [10], DELETE]),
    ("sd25", "limits.max_read", [None, 0, 126, "10", DELETE]),
    ("sd25", "limits.max_write", [None, 0, 124, 10.0, DELETE]),
    ("sd25", "limits.write_multiple", [None, "yes", 1]),
    ("sd25", "persistence", [None, "switchable", DELETE]),
    ("sd25", "persistence.mode", [None, "flash", DELETE]),
    ("sd25", "persistence.switch", [None, "Po505", DELETE]),
    ("sd25", "persistence.switch.code", [None, "Po999", 505, "So-00", DELETE]),
    ("sd25", "persistence.switch.eeprom", [None, "0", 1, 2, DELETE]),
    ("sd25", "persistence.switch.ram", [None, 0, 99, DELETE]),
    ("sd25", "persistence.switch.digit", [None, "Q", 1]),
    ("sd25", "persistence.write_limit", [None, 0, "80000"]),
    ("sd25", "persistence.note", [None, 5, ""]),
    *(("sd25", f"motor.{key}", [None, 0, -1, "1.27", math.inf, DELETE]) for key in ("rated_torque_nm",)),
    ("sd25", "motor.rated_speed_rpm", [None, 0, "3000", DELETE]),
    ("sd25", "motor.max_speed_rpm", [None, 1000, math.nan, DELETE]),
    ("sd25", "motor.rotor_inertia_kgcm2", [None, 0, [0.29], DELETE]),
    ("sd25", "motor.counts_per_rev", [None, 0, 1.5, "131072", DELETE]),
    ("sd25", "motor.source", [None, 5]),
    ("sd25", "unverified_note", [None, 5, ""]),
    ("dsx7e", "conventions", [None, ["load_over_motor"]]),
    ("dsx7e", "conventions.inertia_ratio", [None, "other"]),
    ("sd25", "alarms", [None, {"code": 1}]),
    ("sd25", "alarms.0", [None, "AL-01"]),
    ("sd25", "alarms.0.code", [None, "1", -1, 2, DELETE]),  # 2: a duplicate of alarms[1]
    ("sd25", "alarms.0.display", [None, 1, ""]),
    ("sd25", "alarms.0.name", [None, "", 5, DELETE]),
    ("sd25", "alarms.0.clearable", [None, "yes", 1]),
    ("sd25", "alarms.0.kind", [None, "fire"]),
    ("sd25", "alarms.0.source", [None, 5]),
    ("sd25", "motion_setup", [None, {"code": "Po407"}]),
    ("sd25", "motion_setup.0.code", [None, "Po999", "So-00", 407, DELETE]),
    ("sd25", "motion_setup.0.value", [None, ["X=26"], "Q=1", "X=100", DELETE]),
    ("sd25", "motion_setup.0.reason", [None, "", DELETE]),
    ("sd25", "motion_setup.0.source", [None, 5, DELETE]),
    ("sd25", "motion_setup.0.unverified", [None, 5]),
    ("is620p", "dead_man", [None, "segment"]),
    ("is620p", "dead_man.route", [None, "magic", DELETE]),
    ("is620p", "dead_man.reason", [None, "", DELETE]),
    ("is620p", "dead_man.source", [None, 5, DELETE]),
    ("is620p", "dead_man.unverified", [None, 5]),
    ("is620p", "dead_man.if_host_dies", [None, ["stop"]]),
    ("is620p", "dead_man.start_value", [None, 0, "2", 70000]),
    ("is620p", "dead_man.ramp_reference_rpm", [None, 0, -5, "fast", math.nan, True, [1000]]),
    ("is620p", "dead_man.ramp_source", [None, 5, "", DELETE]),
    ("dsx7e", "dead_man.ramp_reference_rpm", ["Rated", "rpm"]),
    ("sd25", "forced_inputs", [None, "So-58"]),
    ("sd25", "forced_inputs.switch", [None, "So-58", DELETE]),
    ("sd25", "forced_inputs.switch.code", [None, "Nope", 58, DELETE]),
    ("sd25", "forced_inputs.switch.digit", [None, 5, "Q"]),
    ("sd25", "forced_inputs.switch.forced", [None, "1", 100, True]),
    ("sd25", "forced_inputs.switch.released", [None, "0", 1]),
    ("sd25", "forced_inputs.levels", [None, "Nope", 57, DELETE]),
    ("sd25", "forced_inputs.monitor", [None, "Nope", DELETE]),
    ("sd25", "forced_inputs.monitor_shows", [None, "both"]),
    ("sd25", "forced_inputs.source", [None, 5, "", DELETE]),
    ("sd25", "forced_inputs.unverified", [None, 5]),
    ("sd25", "serial.boost", [None, "Po504"]),
    ("sd25", "serial.boost.code", [None, "Nope", DELETE]),
    ("sd25", "serial.boost.to", [None, 12345, "57600", DELETE]),
    ("sd25", "serial.boost.rates", [None, {2: "fast"}, {3: 19200}]),
    ("sd25", "serial.boost.source", [None, 5]),
    ("sd25", "io", [None, ["DI1"]]),
    ("sd25", "io.inputs", [None, "L923"]),
    ("sd25", "io.inputs.monitor", [None, "Nope", 923, DELETE]),
    ("sd25", "io.inputs.source", [None, 5, DELETE]),
    ("sd25", "io.inputs.terminals.0", [None, "DI1"]),
    ("sd25", "io.inputs.terminals.0.bit", [None, "0", 99]),
    ("sd25", "io.inputs.terminals.0.function", [None, "Nope", "Po407.Q", 407]),
    ("sd25", "alarm_causes", [None, ["AL-01"]]),
    ("sd25", "alarm_causes.source", [None, 5, DELETE]),
    ("sd25", "alarm_causes.items.0", [None, "AL-01"]),
    ("sd25", "alarm_causes.items.0.codes", [None, [9999], "1"]),
    ("is620p", "alarm_log", [None, ["H0B-33"]]),
    ("is620p", "alarm_log.source", [None, 5, DELETE]),
    ("is620p", "alarm_log.select", [None, "H0B-33"]),
    ("is620p", "alarm_log.select.code", [None, "Nope", "H0B-34"]),
    ("is620p", "alarm_log.select.past", [None, 0, "9"]),
    ("is620p", "alarm_log.excludes_current", [None, "yes"]),
    ("dsx7e", "unverified_values", [None, "Pn004"]),
    ("dsx7e", "unverified_values.0", [None, "Nope", 5, {"Pn004": ""}]),
    ("sd25", "groups", [None, ["basic"]]),
    ("sd25", "groups.basic", [None, 5, ""]),
    ("sd25", "roles", [None, ["jog"]]),
    ("sd25", "roles.speed_feedback", [None, "Nope", 5, ""]),
    ("sd25", "identity", [None, ["So-00"]]),
    ("sd25", "identity.firmware", [None, "Nope", "Po001"]),
    ("sd25", "identity.checks", [None, [], DELETE]),
    ("sd25", "identity.checks.0.code", [None, "Nope", 0]),
    ("sd25", "identity.checks.0.range", [None, [9999, 100], "100..9999", [100]]),
    ("sd25", "identity.checks.0.sim", [None, "100", 50]),
    ("sd25", "identity.checks.0.source", [None, "", DELETE]),
    ("sd25", "identity.checks.0.unverified", [None, 5]),
    ("sd25", "identity.checks.0.absent", [None, "yes", True]),
]

# (profile, field, the code of the entry to break, bad values)
ENTRY_FIELDS: list[tuple[str, str, str, list[Any]]] = [
    ("sd25", "code", "Po003", [None, 5, "", "Po 3", "Po3.1", "Po3=1", DELETE]),
    ("sd25", "class", "Po101", [None, "Xn", ["Pn"], DELETE]),
    ("sd25", "name", "Po101", [None, "", 3, DELETE]),
    ("sd25", "address", "Po101", [None, -1, 65536, "101", 101.0, True, DELETE]),
    ("sd25", "type", "Po101", [None, "u17", 16]),
    ("sdc", "word_order", "PN10", [None, "middle"]),
    ("sdc", "combine", "PN10", [None, "octal"]),
    ("sdc", "digits", "PN10", [None, 0, 6, "5"]),
    ("dsx7e", "scale", "Pn101", [None, 0, -0.1, "0.1", [0.1], math.nan, math.inf, True, 1e12]),
    ("dsx7e", "unit", "Pn101", [None, ["Hz"], 5, ""]),
    ("sd25", "min", "Po101", [None, "0", 1.5, -1, 70000]),
    ("sd25", "max", "Po101", [None, 70000, "100", -1]),
    ("sd25", "default", "Po101", [None, "ten", 1.5, 70000, DELETE]),
    ("sd25", "access", "Po101", [None, "rx", 5]),
    ("sd25", "effect", "Po101", [None, "later", DELETE]),
    ("sd25", "group", "Po101", [None, 5, "nosuch"]),
    ("sd25", "description", "Po008", [None, 5, ""]),
    ("sd25", "source", "Po101", [None, "", 5, DELETE]),
    ("sd25", "unverified", "Po001", [None, True, 5, ["x"], ""]),
    ("sd25", "format", "Po001", [None, "oct", DELETE]),
    ("sd25", "fields", "Po001", [None, "XY", ["X", 2], ["X", "x"], [], DELETE]),
    ("sd25", "field_width", "Po001", [None, 6, "8"]),
    ("sd25", "field_ranges", "Po001", [None, {"Q": [0, 1]}, {"X": [0, 100]}, {"X": [2, 1]}, {"X": [5, 9]}, [0, 1]]),
    ("sd25", "field_enums", "Po001", [None, {"Q": {0: "a"}}, {"X": "a"}, {"X": {0: 5}}, {}]),
    ("sd25", "bits", "So-57", [None, {16: "x"}, {"a": "b"}, {0: None}, [], DELETE]),
    ("sd25", "enum", "Po008", [None, {"a": "b"}, {0: 5}, {0: "on", 1: "ON"}, {7: "x"}, {1: "a"}]),
    ("sd25", "trigger", "Po008", [None, "1", 70000]),
    ("sd25", "trigger", "Po101", [1]),  # only functions have one
    ("sd25", "copy", "Po101", [None, "no", 1]),
]


def _set(data: dict[str, Any], path: str, value: Any) -> None:
    *parents, last = path.split(".")
    node: Any = data
    for key in parents:
        node = node[int(key)] if isinstance(node, list) else node[key]
    key = int(last) if isinstance(node, list) else last
    if value is DELETE:
        del node[key]
    else:
        node[key] = value


def _one_problem(pid: str, mutate: Any, tmp_path: Path) -> str:
    data = copy.deepcopy(shipped(pid))
    mutate(data)
    where = str(tmp_path / f"{pid}.yaml")
    profile, problems = parse_profile(data, where)
    assert profile is None, "the mutant was accepted"
    assert len(problems) == 1, problems
    assert problems[0].startswith(f"{where}: "), problems
    return problems[0]


def _label(value: Any) -> str:
    return "DELETE" if value is DELETE else repr(value)


@pytest.mark.parametrize(
    ("pid", "path", "bad"),
    [(pid, path, bad) for pid, path, values in FIELDS for bad in values],
    ids=[f"{pid}:{path}={_label(bad)}" for pid, path, values in FIELDS for bad in values],
)
def test_a_broken_top_level_field_is_one_line_naming_it(tmp_path, pid, path, bad):
    line = _one_problem(pid, lambda d: _set(d, path, bad), tmp_path)
    *section, field = path.split(".")
    named = ".".join(f"[{p}]" if p.isdigit() else p for p in section).replace(".[", "[")
    assert named in line, line  # the section (alarms[0], serial, ...)
    assert field.isdigit() or field in line, line


@pytest.mark.parametrize(
    ("pid", "field", "code", "bad"),
    [(pid, field, code, bad) for pid, field, code, values in ENTRY_FIELDS for bad in values],
    ids=[f"{pid}:{code}.{field}={_label(bad)}" for pid, field, code, values in ENTRY_FIELDS for bad in values],
)
def test_a_broken_entry_field_is_one_line_naming_the_entry_and_the_field(tmp_path, pid, field, code, bad):
    index = next(i for i, e in enumerate(shipped(pid)["entries"]) if e["code"] == code)
    line = _one_problem(pid, lambda d: _set(d, f"entries.{index}.{field}", bad), tmp_path)
    assert f"entries[{index}]" in line and field in line, line
    if field != "code":
        assert f"({code})" in line, line


def test_every_field_of_the_schema_has_its_mutants():
    """SCHEMA.md's keys are all broken above: a field added to the schema needs its mutants here."""
    from servotool.model.entry_schema import ENTRY_KEYS
    from servotool.model.schema import TOP_KEYS

    tested_entry = {field for _, field, _, _ in ENTRY_FIELDS}
    assert ENTRY_KEYS == tested_entry
    tested_top = {path.split(".")[0] for _, path, _ in FIELDS}
    assert TOP_KEYS == tested_top
    schema = (builtin_dir().parent / "profiles" / "SCHEMA.md").read_text(encoding="utf-8")
    for key in ENTRY_KEYS | TOP_KEYS:
        assert f"{key}:" in schema, f"SCHEMA.md does not list '{key}'"


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("entries.{Pn101}.scale", None, "(Pn101).scale: expected a number, got nothing (null)"),
        ("entries.{Pn101}.unit", ["Hz"], '(Pn101).unit: expected a string, got ["Hz"]'),
        ("serial.unit", 0, "serial.unit: 0 is the broadcast address, which no drive answers"),
    ],
)
def test_profiles_check_and_loading_with_p_refuse_a_mutant_with_one_line(cli, tmp_path, field, value, message):
    """Issue 30's three: `scale: null` was shown as 1 (Pn101 180 instead of 18.0), `unit: ['Hz']` literally, and
    `serial.unit: 0` (broadcast) accepted."""
    data = copy.deepcopy(shipped("dsx7e"))
    if field.startswith("entries."):
        index = next(i for i, e in enumerate(data["entries"]) if e["code"] == "Pn101")
        field = field.replace("{Pn101}", str(index))
    _set(data, field, value)
    path = tmp_path / "dsx7e.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True, sort_keys=False), encoding="utf-8")
    r = cli("profiles", "check", str(path))
    assert r.code == 2 and r.out.strip().splitlines() == [r.out.strip()], r.out
    assert r.out.startswith(f"{path}: ") and message in r.out, r.out
    r = cli("--port", "sim", "-P", str(path), "param", "get", "Pn101")
    assert r.code == 2, (r.out, r.err)
    assert r.err.strip().splitlines() == [r.err.strip()] and message in r.err and str(path) in r.err, r.err
    assert "Pn101" not in r.out
