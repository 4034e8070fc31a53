"""Scripted commissioning plans: a YAML list of servotool steps, validated whole before the first one runs.

Plan file::

    port: sim              # optional; command-line options win
    profile: dsx7e
    units: [1, 2]          # several axes on one line
    steps:
      - set: {Pn100: 40.0, Pn101: 25.0}
      - expect: {Pn100: 40.0, Un000: {value: 0, tol: 5}}
      - tune inertia: {rigidity: 12}
      - backup: axis-{unit}.yaml
      - jog: {speed: 200, time: 1}
      - wait: 0.5
      - alarm clear:
      - save:
      - prompt: Check the brake is released
      - restore: axis-{unit}.yaml
    # any step may carry `unit: N` (or a list) to run on some axes only

Only these step names exist; values are data (safe YAML), nothing else can run.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from servotool import alarms
from servotool.codec import format_value, parse_value, raw_to_eng
from servotool.connection import options_from
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError, UsageError, VerifyError
from servotool.motion import motion_route
from servotool.profile import Entry, Profile

STEP_NAMES = ("set", "expect", "backup", "restore", "jog", "tune inertia", "wait", "alarm clear", "save", "prompt")
TOP_KEYS = {"port", "profile", "units", "unit", "steps", "baud", "parity", "stopbits", "timeout", "retries"}
JOG_KEYS = {"speed", "time", "max_travel"}
TUNE_KEYS = {"rigidity", "bandwidth", "travel", "max_speed", "accel_time", "direction", "repeats", "gains"}


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
    options: dict[str, Any]
    units: list[int]
    steps: list[Step]


@dataclass
class StepResult:
    step: Step
    unit: int
    ok: bool
    detail: str
    seconds: float
    data: dict[str, Any] = field(default_factory=dict)

    def as_json(self) -> dict[str, Any]:
        return {"step": self.step.index + 1, "line": self.step.line, "name": self.step.name, "unit": self.unit,
                "ok": self.ok, "detail": self.detail, "seconds": round(self.seconds, 3), **self.data}


def _fail(path: Path, line: int, msg: str) -> UsageError:
    return UsageError(f"{path}:{line}: {msg}")


def load_plan(path: Path) -> Plan:
    """Parse and structurally check a plan (profile-dependent checks come in validate())."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise UsageError(f"cannot read plan {path}: {exc.strerror}") from None
    except UnicodeDecodeError as exc:
        raise UsageError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark else 1
        raise _fail(path, line, f"invalid YAML: {getattr(exc, 'problem', exc)}") from None
    if not isinstance(data, dict) or not isinstance(root, yaml.MappingNode):
        raise _fail(path, 1, "a plan is a mapping with 'steps:'")
    key_lines: dict[str, int] = {}
    for k, _v in root.value:
        if k.value in key_lines:
            raise _fail(path, k.start_mark.line + 1, f"'{k.value}' is given twice")
        key_lines[k.value] = k.start_mark.line + 1
    for key in data:
        if key not in TOP_KEYS:
            raise _fail(path, key_lines.get(str(key), 1),
                        f"unknown key '{key}' (known: {', '.join(sorted(TOP_KEYS))})")
    try:
        options_from({k: v for k, v in data.items() if k not in ("steps", "units", "unit")}, "plan")
    except UsageError as exc:
        bad = next((k for k in data if f" {k} must" in str(exc)), "")
        raise _fail(path, key_lines.get(bad, 1), str(exc).removeprefix("plan: ")) from None
    units = _unit_list(data.get("units", data.get("unit")))
    if units is False:
        raise _fail(path, key_lines.get("units", key_lines.get("unit", 1)),
                    "units must be a list of different unit ids 1..247")
    steps_node = next((v for k, v in root.value if k.value == "steps"), None)
    raw_steps = data.get("steps")
    if not isinstance(raw_steps, list) or not raw_steps or steps_node is None:
        raise _fail(path, 1, "'steps:' must be a non-empty list")
    steps = []
    for i, (raw, node) in enumerate(zip(raw_steps, steps_node.value, strict=True)):
        line = node.start_mark.line + 1
        if not isinstance(raw, dict):
            raise _fail(path, line, f"step {i + 1}: expected '- NAME: ARGUMENT'")
        names = [k for k in raw if k != "unit"]
        if len(names) != 1 or names[0] not in STEP_NAMES:
            raise _fail(path, line, f"step {i + 1}: unknown step {names or raw!r} "
                                    f"(steps: {', '.join(STEP_NAMES)})")
        step_units = _unit_list(raw.get("unit"))
        if step_units is False:
            raise _fail(path, line, f"step {i + 1}: unit must be an id or a list of different ids 1..247")
        if step_units and not units:
            raise _fail(path, line, f"step {i + 1}: 'unit:' on a step needs the plan's 'units:' list")
        steps.append(Step(i, line, names[0], raw[names[0]], step_units))
    options = {k: v for k, v in data.items() if k not in ("steps", "units", "unit")}
    return Plan(path, options, units or [], steps)


def _unit_list(value: Any) -> list[int] | bool | None:
    """A unit id or list of them as a list; None when absent; False when malformed."""
    if value is None:
        return None
    ids = [value] if isinstance(value, int) else value
    ok = (isinstance(ids, list) and ids and len(set(ids)) == len(ids)
          and all(isinstance(u, int) and not isinstance(u, bool) and 1 <= u <= 247 for u in ids))
    return ids if ok else False


def _number(value: Any, what: str, low: float, high: float) -> float:
    """A number from a plan (YAML true/false are not numbers), within [low, high]."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        raise UsageError(f"{what} must be a number {low:g}..{high:g}, got {value!r}")
    return float(value)


def _no_argument(step: Step) -> None:
    if step.arg is not None:
        raise UsageError(f"'{step.name}' takes no argument (got {step.arg!r})")


def _assignments(step: Step, profile: Profile) -> list[tuple[Entry, int]]:
    if not isinstance(step.arg, dict) or not step.arg:
        raise UsageError(f"{step.where()}: expected a mapping CODE: VALUE")
    out = []
    for code, value in step.arg.items():
        entry = profile.entry(str(code))
        if entry.cls != "Pn" or not entry.writable:
            raise UsageError(f"{step.where()}: {entry.code} is not a settable parameter")
        out.append((entry, parse_value(entry, str(value))))
    return out


@dataclass(frozen=True)
class Expectation:
    entry: Entry
    low: float
    high: float

    def describe(self) -> str:
        return f"{self.entry.code} in [{self.low:g}, {self.high:g}] {self.entry.unit}".rstrip()


def _expectations(step: Step, profile: Profile) -> list[Expectation]:
    if not isinstance(step.arg, dict) or not step.arg:
        raise UsageError(f"{step.where()}: expected a mapping CODE: VALUE or CODE: {{value, tol}} / {{min, max}}")
    out = []
    for code, spec in step.arg.items():
        entry = profile.entry(str(code))
        if not entry.readable:
            raise UsageError(f"{step.where()}: {entry.code} cannot be read")
        half = entry.scale / 2
        try:
            if isinstance(spec, dict):
                extra = set(spec) - {"value", "tol", "min", "max"}
                if extra:
                    raise UsageError(f"{step.where()}: unknown expect key(s) {', '.join(map(str, extra))}")
                if "value" in spec and ("min" in spec or "max" in spec):
                    raise UsageError(f"{step.where()}: {entry.code}: give value (and tol) or min/max, not both")
                if "value" in spec:
                    tol = float(spec.get("tol", half))
                    if tol < 0:
                        raise UsageError(f"{step.where()}: {entry.code}: tol must be >= 0")
                    low, high = float(spec["value"]) - tol, float(spec["value"]) + tol
                elif "min" in spec or "max" in spec:
                    low, high = float(spec.get("min", "-inf")), float(spec.get("max", "inf"))
                    if low > high:
                        raise UsageError(f"{step.where()}: {entry.code}: min {low:g} is above max {high:g}")
                else:
                    raise UsageError(f"{step.where()}: {entry.code}: give value (and tol) or min and/or max")
            else:
                v = raw_to_eng(entry, parse_value(entry, str(spec)))
                low, high = float(v) - half, float(v) + half
        except (TypeError, ValueError):
            raise UsageError(f"{step.where()}: bad expectation for {entry.code}: {spec!r}") from None
        out.append(Expectation(entry, low, high))
    return out


def validate(plan: Plan, profile: Profile) -> list[str]:
    """Check every step against the profile before anything runs; returns a description per step."""
    lines = []
    for step in plan.steps:
        try:
            lines.append(_describe(step, profile, plan))
        except UsageError as exc:
            msg = str(exc)
            raise UsageError(msg if msg.startswith("step ") else f"{step.where()}: {msg}") from None
    return [f"{plan.path}:{s.line}: {d}" for s, d in zip(plan.steps, lines, strict=True)]


def _describe(step: Step, profile: Profile, plan: Plan) -> str:
    name, arg = step.name, step.arg
    if step.units and plan.units and not set(step.units) <= set(plan.units):
        raise UsageError(f"unit {step.units} is not among the plan's units {plan.units}")
    if name == "set":
        return "set " + ", ".join(f"{e.code}={format_value(e, raw)}" for e, raw in _assignments(step, profile))
    if name == "expect":
        return "expect " + ", ".join(x.describe() for x in _expectations(step, profile))
    if name in ("backup", "restore"):
        if not isinstance(arg, str) or not arg:
            raise UsageError("expected a file name")
        return f"{name} {arg}"
    if name == "jog":
        if not isinstance(arg, dict) or set(arg) - JOG_KEYS or "speed" not in arg or "time" not in arg:
            raise UsageError("jog needs {speed: RPM, time: S} (optional max_travel)")
        route = motion_route(profile, "jog")           # a JOG trigger or speed reference + servo-on
        speed, secs = _number(arg["speed"], "jog speed", -100_000, 100_000), _number(arg["time"], "jog time", 0, 600)
        if speed == 0 or secs == 0:
            raise UsageError("jog speed must be non-zero and time 0..600 s")
        parse_value(route.speed_entry, f"{abs(speed):g}")
        if "max_travel" in arg:
            limit = _number(arg["max_travel"], "jog max_travel", 0, 10_000)
            if abs(speed) / 60 * secs > limit:
                raise UsageError(f"a {secs:g} s JOG at {abs(speed):g} rpm travels about {abs(speed) / 60 * secs:.2f} "
                                 f"rev, over its max_travel {limit:g} rev")
        return f"jog {speed:g} rpm for {secs:g} s"
    if name == "tune inertia":
        motion_route(profile, "tune inertia")
        for role in ("jog_accel", "speed_feedback", "torque_feedback", "inertia_ratio"):
            profile.need_role(role, "tune inertia")
        opts = tune_options(arg, profile)
        return f"tune inertia: {opts.motion.describe()}" + ("" if opts.gains else "; gains left as they are")
    if name == "wait":
        if not isinstance(arg, int | float) or isinstance(arg, bool) or not 0 <= arg <= 3600:
            raise UsageError("wait takes seconds 0..3600")
        return f"wait {arg:g} s"
    if name == "alarm clear":
        _no_argument(step)
        profile.need_role("alarm_reset", "alarm clear")
        return "clear the alarm"
    if name == "save":
        _no_argument(step)
        mode = profile.persistence.mode
        if mode == "ram":
            profile.need_role("eeprom_save", "save")
            return "store parameters in EEPROM"
        if mode == "switchable":
            return (f"store the values this plan wrote in EEPROM (rewritten with {profile.persistence.switch_code} "
                    "set to EEPROM, then put back)")
        return "save (the drive stores every write already)"
    if name == "prompt":
        if not isinstance(arg, str) or not arg:
            raise UsageError("prompt takes the question to ask")
        return f"ask: {arg}"
    raise UsageError(f"unknown step {name}")


@dataclass(frozen=True)
class TuneOptions:
    motion: Any                  # wizard.MotionPlan, before the link's sampling rate is known
    rigidity: int | None
    bandwidth: float | None
    gains: bool
    motion_options: dict[str, Any]   # for wizard.plan_host_motion; unset ones automatic, as in the CLI


def tune_options(arg: Any, profile: Profile) -> TuneOptions:
    """A 'tune inertia' step's options, checked as the wizard checks them (before anything moves)."""
    from servotool.tuning import wizard
    from servotool.tuning.gains import suggest_gains

    opts = arg or {}
    if not isinstance(opts, dict) or set(opts) - TUNE_KEYS:
        raise UsageError(f"tune inertia options are {', '.join(sorted(TUNE_KEYS))}")
    direction = opts.get("direction", "both")
    if not isinstance(direction, str):
        raise UsageError("tune inertia direction must be both, forward or reverse")
    repeats = _number(opts["repeats"], "tune inertia repeats", 1, 20) if "repeats" in opts else None
    if repeats is not None and repeats != int(repeats):
        raise UsageError("tune inertia repeats must be a whole number 1..20")
    motion_options = {
        "max_speed": _number(opts["max_speed"], "tune inertia max_speed", 0, 100_000) if "max_speed" in opts else None,
        "accel_time_ms": _number(opts["accel_time"], "tune inertia accel_time", 20, 5000) if "accel_time" in opts
        else None,
        "travel_rev": _number(opts.get("travel", 2.0), "tune inertia travel", 0, 10_000), "direction": direction,
        "repeats": None if repeats is None else int(repeats)}
    motion = wizard.plan_motion(profile, **motion_options)
    gains = opts.get("gains", True)
    if not isinstance(gains, bool):
        raise UsageError("tune inertia gains must be true or false")
    rigidity, bandwidth = opts.get("rigidity"), opts.get("bandwidth")
    if rigidity is not None and (isinstance(rigidity, bool) or not isinstance(rigidity, int)):
        raise UsageError(f"tune inertia rigidity must be a whole number, got {rigidity!r}")
    if bandwidth is not None:
        bandwidth = _number(bandwidth, "tune inertia bandwidth", 0, 10_000)
    if gains and profile.motor is not None and (rigidity is not None or bandwidth is not None):
        try:  # the same rules the gains will be computed with, on a nominal load
            suggest_gains(rotor_inertia_kgcm2=profile.motor.rotor_inertia_kgcm2, load_ratio=1.0,
                          rigidity=rigidity, bandwidth_hz=bandwidth)
        except ValueError as exc:
            raise UsageError(f"tune inertia: {exc}") from None
    return TuneOptions(motion, rigidity, bandwidth, gains, motion_options)


def _path(plan: Plan, text: str, unit: int, several: bool) -> Path:
    name = text.replace("{unit}", str(unit))
    if several and "{unit}" not in text:
        p = Path(name)
        name = str(p.with_name(f"{p.stem}-unit{unit}{p.suffix}"))
    path = Path(name)
    return path if path.is_absolute() else plan.path.parent / path


class Runner:
    """Runs a validated plan on open drives."""

    def __init__(self, plan: Plan, drives: list[Drive], *, yes: bool, continue_on_error: bool,
                 ask: Callable[[int, str], bool], log: Callable[[str], None]) -> None:
        self.plan, self.drives, self.yes = plan, drives, yes
        self.continue_on_error, self.ask, self.log = continue_on_error, ask, log
        self.results: list[StepResult] = []
        self.written: dict[int, dict[str, tuple[Entry, int]]] = {d.unit: {} for d in drives}   # for 'save'

    def _wrote(self, d: Drive, entry: Entry, raw: int) -> None:
        self.written[d.unit][entry.code] = (entry, raw)

    def check_units(self) -> None:
        """Every axis answers before the first step writes anything."""
        for d in self.drives:
            probe = d.profile.role("alarm_code") or next(e for e in d.profile.entries if e.readable)
            try:
                d.read_entries([probe])
            except DeviceError as exc:
                raise DeviceError(f"unit {d.unit} does not answer, so nothing was run: {exc}") from None

    def run(self) -> bool:
        several = len(self.drives) > 1
        for step in self.plan.steps:
            for drive in self.drives:
                if step.units and drive.unit not in step.units:
                    continue
                t0 = time.monotonic()
                try:
                    detail, data = self._run(step, drive, several)
                    ok = True
                except ServoError as exc:
                    detail, data, ok = str(exc), {"error": type(exc).__name__, "exit_code": exc.exit_code}, False
                result = StepResult(step, drive.unit, ok, detail, time.monotonic() - t0, data)
                self.results.append(result)
                self.log(f"{'ok  ' if ok else 'FAIL'} unit {drive.unit} {step.where()}: {detail}")
                if not ok and not self.continue_on_error:
                    return False
        return all(r.ok for r in self.results)

    def _run(self, step: Step, d: Drive, several: bool) -> tuple[str, dict[str, Any]]:
        from servotool import params

        name, arg = step.name, step.arg
        if name == "set":
            texts = [f"{e.code}={raw}" for e, raw in _assignments(step, d.profile)]
            plan = params.plan_set(d, texts, raw=True)
            done = params.apply_set(d, plan)
            for r in done:
                self._wrote(d, r.entry, r.new)
            return (f"{len(done)} written, {len(plan.unchanged)} already set",
                    {"written": {r.entry.code: format_value(r.entry, r.new) for r in done}})
        if name == "expect":
            exps = _expectations(step, d.profile)
            readings = d.read_entries([x.entry for x in exps])
            values = {x.entry.code: float(r.eng) for x, r in zip(exps, readings, strict=True)}
            bad = [f"{x.entry.code}={values[x.entry.code]:g} not in [{x.low:g}, {x.high:g}]"
                   for x in exps if not x.low <= values[x.entry.code] <= x.high]
            if bad:
                raise VerifyError("expectation failed: " + "; ".join(bad))
            return "as expected", {"values": values}
        if name == "backup":
            from servotool import backup

            path = _path(self.plan, arg, d.unit, several)
            written = backup.write_backup(d, path, force=True)
            return f"saved to {written}", {"file": str(written)}
        if name == "restore":
            from servotool import backup

            path = _path(self.plan, arg, d.unit, several)
            report = backup.restore_file(d, path)
            return report, {"file": str(path)}
        if name == "jog":
            from servotool.motion import Jogger

            jogger = Jogger(d)
            jplan = jogger.plan(float(arg["speed"]), float(arg["time"]), arg.get("max_travel"))
            jogger.run(jplan)
            return jplan.describe(), {}
        if name == "tune inertia":
            return self._tune(d, step.arg or {})
        if name == "wait":
            time.sleep(float(arg))
            return f"waited {arg:g} s", {}
        if name == "alarm clear":
            before = alarms.current(d)
            alarms.clear(d)
            return (f"cleared {before.display} {before.name}" if before.active else "no alarm was active"), {}
        if name == "save":
            return self._save(d)
        if name == "prompt":
            if self.yes:
                return f"skipped (--yes): {arg}", {}
            if not self.ask(d.unit, str(arg)):
                raise UsageError(f"operator declined: {arg}")
            return f"confirmed: {arg}", {}
        raise UsageError(f"unknown step {name}")

    def _save(self, d: Drive) -> tuple[str, dict[str, Any]]:
        """Make what the plan wrote survive a power cycle, the way this drive does it."""
        mode = d.profile.persistence.mode
        if mode == "ram":
            d.trigger("eeprom_save", "save")
            return "parameters stored in EEPROM", {}
        if mode == "immediate":
            return "nothing to do: the drive stores every write", {}
        from servotool.params import persistence

        written = list(self.written[d.unit].values())
        with persistence(d, save=True):
            for entry, raw in written:     # the same value again, now with the switch set to EEPROM
                d.write_raw(entry, raw)
        return (f"{len(written)} values stored in EEPROM", {"stored": [e.code for e, _ in written]})

    def _tune(self, d: Drive, arg: Any) -> tuple[str, dict[str, Any]]:
        from servotool.tuning import wizard

        opts = tune_options(arg, d.profile)
        wizard.preflight(d, "host")
        motion, rest = wizard.plan_host_motion(d, **opts.motion_options)
        result = wizard.Identifier(d).run_host(motion, rest=rest)
        entry, raw = wizard.ratio_raw(d, result.new_ratio)
        d.write_verified(entry, raw)
        self._wrote(d, entry, raw)
        data: dict[str, Any] = {"ratio": round(result.new_ratio, 4), entry.code: raw * entry.scale}
        if opts.gains:
            _, changes = wizard.gain_changes(d, result.new_ratio, rigidity=opts.rigidity, bandwidth_hz=opts.bandwidth)
            for c in changes:
                d.write_verified(c.entry, c.raw)
                self._wrote(d, c.entry, c.raw)
            data["gains"] = {c.entry.code: c.new for c in changes}
        return f"load ratio {result.new_ratio:.2f} -> {entry.code}={raw * entry.scale:g}", data


def write_report(path: Path, plan: Plan, results: list[StepResult], ok: bool, seconds: float, *,
                 profile: str, port: str, units: list[int]) -> dict[str, Any]:
    from servotool import __version__

    report = {"plan": str(plan.path), "ok": ok, "profile": profile, "port": port, "units": units,
              "tool_version": __version__, "seconds": round(seconds, 2),
              "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "steps": [r.as_json() for r in results]}
    try:
        path.write_text(json.dumps(report, indent=2, default=str) + "\n")
    except OSError as exc:
        raise UsageError(f"cannot write report {path}: {exc.strerror}") from None
    return report
