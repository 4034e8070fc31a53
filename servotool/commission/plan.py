"""Commissioning plans: the YAML file format and its loading, with line numbers for every step."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from servotool.connection import options_from
from servotool.errors import UsageError
from servotool.files import compose_yaml, parse_yaml, read_text

STEP_NAMES = (
    "set",
    "expect",
    "backup",
    "restore",
    "jog",
    "tune inertia",
    "tune score",
    "tune friction",
    "tune notch",
    "tune gain-switching",
    "wait",
    "alarm clear",
    "save",
    "prompt",
)


CONNECTION_KEYS = {"port", "profile", "baud", "parity", "stopbits", "timeout", "retries"}


# allow_outside: the files the plan names may lie outside its folder; overwrite: the files it writes may replace
# existing ones (a backup step may also say it for its own file).
FILE_KEYS = {"allow_outside", "overwrite"}


TOP_KEYS = CONNECTION_KEYS | FILE_KEYS | {"units", "unit", "steps"}


JOG_KEYS = {"speed", "time", "max_travel", "no_dead_man"}


TUNE_KEYS = {
    "rigidity",
    "bandwidth",
    "travel",
    "max_speed",
    "accel_time",
    "direction",
    "repeats",
    "gains",
    "check",
    "report",
    "no_dead_man",
}


@dataclass
class Step:
    index: int
    line: int
    name: str
    arg: Any
    units: list[int] | None

    def where(self) -> str:
        return f"step {self.index + 1} ({self.name}, line {self.line})"


@dataclass
class Plan:
    path: Path
    options: dict[str, Any]  # connection options
    units: list[int]
    steps: list[Step]
    problems: list[str] = field(default_factory=list)  # step errors found while loading, reported by validate
    allow_outside: bool = False
    overwrite: bool = False


def _fail(path: Path, line: int, msg: str) -> UsageError:
    return UsageError(f"{path}:{line}: {msg}")


def load_plan(path: Path) -> Plan:
    """Parse and structurally check a plan (profile-dependent checks come in validate())."""
    text = read_text(path)
    root, data = compose_yaml(text, path), parse_yaml(text, path)
    if not isinstance(data, dict) or not isinstance(root, yaml.MappingNode):
        raise _fail(path, 1, "a plan is a mapping with 'steps:'")
    key_lines: dict[str, int] = {}
    for k, _v in root.value:
        if k.value in key_lines:
            raise _fail(path, k.start_mark.line + 1, f"'{k.value}' is given twice")
        key_lines[k.value] = k.start_mark.line + 1
    for key in data:
        if key not in TOP_KEYS:
            raise _fail(path, key_lines.get(str(key), 1), f"unknown key '{key}' (known: {', '.join(sorted(TOP_KEYS))})")
    for key in FILE_KEYS & set(data):
        if not isinstance(data[key], bool):
            raise _fail(path, key_lines[key], f"{key} must be true or false, got {data[key]!r}")
    options = {k: v for k, v in data.items() if k in CONNECTION_KEYS}
    try:
        options_from(options, "plan")
    except UsageError as exc:
        bad = next((k for k in data if f" {k} must" in str(exc)), "")
        raise _fail(path, key_lines.get(bad, 1), str(exc).removeprefix("plan: ")) from None
    units = _unit_list(data.get("units", data.get("unit")))
    if units is False:
        raise _fail(
            path, key_lines.get("units", key_lines.get("unit", 1)), "units must be a list of different unit ids 1..247"
        )
    steps_node = next((v for k, v in root.value if k.value == "steps"), None)
    raw_steps = data.get("steps")
    if not isinstance(raw_steps, list) or not raw_steps or steps_node is None:
        raise _fail(path, 1, "'steps:' must be a non-empty list")
    steps, problems = [], []
    for i, (raw, node) in enumerate(zip(raw_steps, steps_node.value, strict=True)):
        try:
            steps.append(_step(path, i, raw, node.start_mark.line + 1, units))
        except UsageError as exc:  # every step's problem is reported, in one pass (validate raises)
            problems.append(str(exc))
    return Plan(
        path,
        options,
        units or [],
        steps,
        problems,
        allow_outside=data.get("allow_outside", False),
        overwrite=data.get("overwrite", False),
    )


def _step(path: Path, i: int, raw: Any, line: int, units: list[int] | bool | None) -> Step:
    if not isinstance(raw, dict):
        raise _fail(path, line, f"step {i + 1}: expected '- NAME: ARGUMENT'")
    names = [k for k in raw if k != "unit"]
    if len(names) != 1 or names[0] not in STEP_NAMES:
        raise _fail(path, line, f"step {i + 1}: unknown step {names or raw!r} (steps: {', '.join(STEP_NAMES)})")
    step_units = _unit_list(raw.get("unit"))
    if step_units is False:
        raise _fail(path, line, f"step {i + 1}: unit must be an id or a list of different ids 1..247")
    if step_units and not units:
        raise _fail(path, line, f"step {i + 1}: 'unit:' on a step needs the plan's 'units:' list")
    return Step(i, line, names[0], raw[names[0]], step_units)


def _unit_list(value: Any) -> list[int] | bool | None:
    """A unit id or list of them as a list; None when absent; False when malformed."""
    if value is None:
        return None
    ids = [value] if isinstance(value, int) else value
    ok = (
        isinstance(ids, list)
        and ids
        and len(set(ids)) == len(ids)
        and all(isinstance(u, int) and not isinstance(u, bool) and 1 <= u <= 247 for u in ids)
    )
    return ids if ok else False
