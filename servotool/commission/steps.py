"""Plan steps: validation and description of each step type before anything is written."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from servotool.commission.plan import JOG_KEYS, TUNE_KEYS, Plan, Step, _number
from servotool.errors import UsageError
from servotool.model.codec import format_value, parse_value, raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.model.roles import motion_route
from servotool.tuning import planning


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
    motion: Any                  # planning.MotionPlan, before the link's sampling rate is known
    rigidity: int | None
    bandwidth: float | None
    gains: bool
    motion_options: dict[str, Any]   # for planning.plan_host_motion; unset ones automatic, as in the CLI


def tune_options(arg: Any, profile: Profile) -> TuneOptions:
    """A 'tune inertia' step's options, checked as the wizard checks them (before anything moves)."""
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
    motion = planning.plan_motion(profile, **motion_options)
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
