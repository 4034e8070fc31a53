"""Plan steps on parameters: set, expect, backup, restore, save."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.commission.plan import Step
from servotool.commission.plan_files import FileUse
from servotool.commission.step_type import Outcome, RunContext, StepType, no_argument
from servotool.drive import Drive
from servotool.errors import UsageError, VerifyError
from servotool.model.codec import format_value, json_value, parse_value, raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.ops import backup, changelog, params, restore
from servotool.ops.eeprom import check_power_cycle, persistence
from servotool.ops.journal import port_lock
from servotool.words import count


class SetStep(StepType):
    """`set: {CODE: VALUE, ...}`: write parameters (each verified), skipping those already set."""

    name = "set"

    def assignments(self, step: Step, profile: Profile) -> list[tuple[Entry, int]]:
        if not isinstance(step.arg, dict) or not step.arg:
            raise UsageError(f"{step.where()}: expected a mapping CODE: VALUE")
        out = []
        for code, value in step.arg.items():
            entry = profile.entry(str(code))
            if entry.cls != "Pn" or not entry.writable:
                raise UsageError(f"{step.where()}: {entry.code} is not a settable parameter")
            out.append((entry, parse_value(entry, str(value))))
        return out

    def describe(self, step: Step, profile: Profile) -> str:
        return "set " + ", ".join(f"{e.code}={format_value(e, raw)}" for e, raw in self.assignments(step, profile))

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        texts = [f"{e.code}={raw}" for e, raw in self.assignments(step, drive.profile)]
        # Read and written under the port's lock: no other process writes these or flips the switch meanwhile.
        with port_lock(drive):
            plan = params.prepare_set(drive, texts, raw=True)
            if not any(st.name == "save" and st.index > step.index for st in ctx.plan.steps):
                # no later 'save:' stores it: a power-cycle parameter kept in RAM would be lost by that power cycle
                check_power_cycle(drive, [e for e, _, _ in plan.changes], None)
            with persistence(drive, None):
                done = params.apply_set(drive, plan)
        for r in done:
            ctx.wrote(drive, r.entry, r.new)
        for entry, raw in plan.unchanged:  # already in RAM, maybe not in EEPROM: 'save:' stores them too
            ctx.wrote(drive, entry, raw)
        return Outcome(
            f"{len(done)} written, {len(plan.unchanged)} already set",
            {"written": {r.entry.code: json_value(r.entry, r.new) for r in done}},
        )


@dataclass(frozen=True)
class Expectation:
    entry: Entry
    low: float
    high: float

    def describe(self) -> str:
        return f"{self.entry.code} in [{self.low:g}, {self.high:g}] {self.entry.unit}".rstrip()


class ExpectStep(StepType):
    """`expect: {CODE: VALUE | {value, tol} | {min, max}}`: read and compare; a mismatch fails with exit 3."""

    name = "expect"

    def expectations(self, step: Step, profile: Profile) -> list[Expectation]:
        if not isinstance(step.arg, dict) or not step.arg:
            raise UsageError(f"{step.where()}: expected a mapping CODE: VALUE or CODE: {{value, tol}} / {{min, max}}")
        out = []
        for code, spec in step.arg.items():
            entry = profile.entry(str(code))
            if not entry.readable:
                raise UsageError(f"{step.where()}: {entry.code} cannot be read")
            try:
                low, high = self._bounds(step, entry, spec)
            except (TypeError, ValueError):
                raise UsageError(f"{step.where()}: bad expectation for {entry.code}: {spec!r}") from None
            out.append(Expectation(entry, low, high))
        return out

    @staticmethod
    def _bounds(step: Step, entry: Entry, spec: object) -> tuple[float, float]:
        half = entry.scale / 2
        if not isinstance(spec, dict):
            v = raw_to_eng(entry, parse_value(entry, str(spec)))
            return float(v) - half, float(v) + half
        extra = set(spec) - {"value", "tol", "min", "max"}
        if extra:
            raise UsageError(f"{step.where()}: unknown expect key(s) {', '.join(map(str, extra))}")
        if "value" in spec and ("min" in spec or "max" in spec):
            raise UsageError(f"{step.where()}: {entry.code}: give value (and tol) or min/max, not both")
        if "value" in spec:
            tol = float(spec.get("tol", half))
            if tol < 0:
                raise UsageError(f"{step.where()}: {entry.code}: tol must be >= 0")
            return float(spec["value"]) - tol, float(spec["value"]) + tol
        if "min" in spec or "max" in spec:
            low, high = float(spec.get("min", "-inf")), float(spec.get("max", "inf"))
            if low > high:
                raise UsageError(f"{step.where()}: {entry.code}: min {low:g} is above max {high:g}")
            return low, high
        raise UsageError(f"{step.where()}: {entry.code}: give value (and tol) or min and/or max")

    def describe(self, step: Step, profile: Profile) -> str:
        return "expect " + ", ".join(x.describe() for x in self.expectations(step, profile))

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        exps = self.expectations(step, drive.profile)
        readings = drive.read_entries([x.entry for x in exps])
        values = {x.entry.code: r.eng for x, r in zip(exps, readings, strict=True)}  # as the entry holds it
        bad = [
            f"{x.entry.code}={values[x.entry.code]:g} not in [{x.low:g}, {x.high:g}]"
            for x in exps
            if not x.low <= values[x.entry.code] <= x.high
        ]
        if bad:
            raise VerifyError("expectation failed: " + "; ".join(bad))
        # Each value with its unit (the one way JSON gives units), and its meaning where the entry names it.
        found = {
            r.entry.code: {
                "value": values[r.entry.code],
                "unit": r.entry.unit,
                **({"meaning": r.entry.enum[r.raw]} if r.raw in r.entry.enum else {}),
            }
            for r in readings
        }
        return Outcome("as expected", {"values": found})


class _FileStep(StepType):
    def describe(self, step: Step, profile: Profile) -> str:
        if not isinstance(step.arg, str) or not step.arg:
            raise UsageError("expected a file name")
        return f"{self.name} {step.arg}"


class BackupStep(StepType):
    """`backup: FILE` or `backup: {file: FILE, overwrite: true}`: every parameter into a backup file ({unit} in the
    name for each axis); an existing file is replaced only with overwrite: true."""

    name = "backup"

    @staticmethod
    def target(step: Step) -> tuple[str, bool]:
        arg = step.arg
        if isinstance(arg, dict):
            if (
                set(arg) - {"file", "overwrite"}
                or not isinstance(arg.get("file"), str)
                or not isinstance(arg.get("overwrite", False), bool)
            ):
                raise UsageError("backup takes a file name, or {file: NAME, overwrite: true|false}")
            arg, overwrite = arg["file"], arg.get("overwrite", False)
        else:
            overwrite = False
        if not isinstance(arg, str) or not arg:
            raise UsageError("expected a file name")
        return arg, overwrite

    def describe(self, step: Step, profile: Profile) -> str:
        name, overwrite = self.target(step)
        return f"backup {name}" + (" (replacing an existing file)" if overwrite else "")

    def files(self, step: Step, profile: Profile) -> list[FileUse]:
        name, overwrite = self.target(step)
        return [FileUse(name, "backup", overwrite)]

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        name, step_says = self.target(step)
        path, overwrite = ctx.path(name, drive.unit), ctx.may_replace(step_says)
        if path.exists() and not overwrite:  # checked before the run; a file made meanwhile is still kept
            raise UsageError(f"{path} exists; say 'overwrite: true' (in the step or the plan) or pass --force")
        written = backup.write_backup(drive, path, force=overwrite)
        return Outcome(f"saved to {written}", {"file": str(written)})


class RestoreStep(_FileStep):
    """`restore: FILE`: a backup file put back completely."""

    name = "restore"

    def files(self, step: Step, profile: Profile) -> list[FileUse]:
        self.describe(step, profile)
        return [FileUse(step.arg, "restore")]

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        path = ctx.path(step.arg, drive.unit)
        return Outcome(restore.restore_file(drive, path), {"file": str(path)})


class SaveStep(StepType):
    """`save:`: make what the plan wrote survive a power cycle, the way this drive does it."""

    name = "save"

    def describe(self, step: Step, profile: Profile) -> str:
        no_argument(step)
        mode = profile.persistence.mode
        if mode == "ram":
            profile.need_role("eeprom_save", "save")
            return "store parameters in EEPROM"
        if mode == "switchable":
            return (
                f"store the values this plan wrote in EEPROM (rewritten with {profile.persistence.switch_code} "
                "set to EEPROM, then put back)"
            )
        return "save (the drive stores every write already)"

    def run(self, step: Step, drive: Drive, ctx: RunContext) -> Outcome:
        mode = drive.profile.persistence.mode
        written = list(ctx.written.get(drive.unit, {}).values())
        if mode == "ram":
            drive.trigger("eeprom_save", "save")
            changelog.event(drive, "store", memory=changelog.EEPROM, note="the drive's store function: RAM to EEPROM")
            return Outcome("parameters stored in EEPROM", {"stored": [e.code for e, _ in written]})
        if mode == "immediate":
            return Outcome("nothing to do: the drive stores every write", {"stored": [e.code for e, _ in written]})
        with persistence(drive, save=True):
            for entry, raw in written:  # the same value again, now with the switch set to EEPROM
                params.write_one(drive, entry, raw, raw)
        return Outcome(f"{count(len(written), 'value')} stored in EEPROM", {"stored": [e.code for e, _ in written]})
