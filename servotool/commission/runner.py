"""Running a validated plan on one or more axes, and its report."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.commission.plan import Plan, Step
from servotool.commission.steps import _assignments, _expectations, _path, tune_options
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError, UsageError, VerifyError
from servotool.model.codec import format_value
from servotool.model.profile import Entry
from servotool.ops import alarms, backup, params, restore
from servotool.tuning import gain_writes, identify, planning, preflight


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

            path = _path(self.plan, arg, d.unit, several)
            written = backup.write_backup(d, path, force=True)
            return f"saved to {written}", {"file": str(written)}
        if name == "restore":

            path = _path(self.plan, arg, d.unit, several)
            report = restore.restore_file(d, path)
            return report, {"file": str(path)}
        if name == "jog":
            from servotool.motion.jogger import Jogger

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
        from servotool.ops.eeprom import persistence

        written = list(self.written[d.unit].values())
        with persistence(d, save=True):
            for entry, raw in written:     # the same value again, now with the switch set to EEPROM
                d.write_raw(entry, raw)
        return (f"{len(written)} values stored in EEPROM", {"stored": [e.code for e, _ in written]})

    def _tune(self, d: Drive, arg: Any) -> tuple[str, dict[str, Any]]:

        opts = tune_options(arg, d.profile)
        preflight.preflight(d, "host")
        motion, rest = planning.plan_host_motion(d, **opts.motion_options)
        result = identify.Identifier(d).run_host(motion, rest=rest)
        entry, raw = gain_writes.ratio_raw(d, result.new_ratio)
        d.write_verified(entry, raw)
        self._wrote(d, entry, raw)
        data: dict[str, Any] = {"ratio": round(result.new_ratio, 4), entry.code: raw * entry.scale}
        if opts.gains:
            _, changes = gain_writes.gain_changes(d, result.new_ratio, rigidity=opts.rigidity,
                                                 bandwidth_hz=opts.bandwidth)
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
