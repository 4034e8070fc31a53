"""The files a plan names: where each one resolves, and what a run would write, checked before anything moves.

A plan may come from someone else, and a field engineer runs it again and again: a name resolves against the plan's
folder (`~` expanded) and must stay inside it unless the plan says `allow_outside: true`; a file (or a report
folder) that exists is replaced only where the plan or the step says `overwrite: true`, or `run --force` does; a
file to restore must exist or be written by an earlier step. The dry run and the real run make the same check.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

from servotool.commission.plan import Plan, Step
from servotool.errors import UsageError

WRITES = ("backup", "tune report")  # the kinds of file a step writes; "restore" is read


@dataclass(frozen=True)
class FileUse:
    """A file name as a step gives it (before {unit} and the plan's folder): what it is and whether it may replace
    an existing file."""

    name: str
    kind: str  # "backup" (a file), "tune report" (a folder), "restore" (a file read)
    overwrite: bool = False


@dataclass(frozen=True)
class PlanFile:
    """One file (or report folder) a step uses on one axis, resolved."""

    step: Step
    unit: int
    path: Path
    kind: str
    overwrite: bool  # it may replace an existing one (the step, the plan or --force says so)
    exists: bool

    @property
    def writes(self) -> bool:
        return self.kind in WRITES

    def as_json(self) -> dict[str, object]:
        return {
            "step": self.step.index + 1,
            "line": self.step.line,
            "unit": self.unit,
            "kind": self.kind,
            "path": str(self.path),
            "replaces": self.exists and self.writes,
        }


def resolve(plan: Plan, name: str, unit: int, several: bool) -> Path:
    """A file named in the plan: {unit} replaced (several axes and no {unit}: -unitN added), `~` expanded, relative
    to the plan's folder. UsageError when it leaves that folder (symbolic links followed) and the plan does not say
    `allow_outside: true`."""
    text = name.replace("{unit}", str(unit))
    if several and "{unit}" not in name:
        p = Path(text)
        text = str(p.with_name(f"{p.stem}-unit{unit}{p.suffix}"))
    path = Path(text).expanduser()
    path = Path(os.path.normpath(path if path.is_absolute() else plan.path.parent / path))
    folder = plan.path.parent.resolve()
    if not plan.allow_outside and not path.resolve().is_relative_to(folder):
        raise UsageError(
            f"{name} is {path.resolve()}, outside the plan's folder {folder}: a plan's files stay there unless "
            "the plan says 'allow_outside: true'"
        )
    return path


def _exists(path: Path, kind: str) -> bool:
    """A file there, or for a report folder one with anything in it."""
    if kind == "tune report":
        return (path.is_dir() and any(path.iterdir())) or (path.exists() and not path.is_dir())
    return path.exists()


def plan_files(
    plan: Plan, units: list[int], uses: list[tuple[Step, list[FileUse]]], *, force: bool
) -> tuple[list[PlanFile], list[str]]:
    """Every file the plan's steps use on these axes, in run order, and every problem a run would meet with them:
    a name outside the plan's folder, an existing file without overwrite, one file written twice, a file to
    restore that neither exists nor is written by an earlier step."""
    found: list[PlanFile] = []
    problems: list[str] = []
    written: dict[Path, PlanFile] = {}
    for step, names in uses:
        for unit in [u for u in units if not step.units or u in step.units]:
            for use in names:
                try:
                    path = resolve(plan, use.name, unit, len(units) > 1)
                except UsageError as exc:
                    problems.append(f"{step.where()}: {exc}")
                    continue
                overwrite = use.overwrite or plan.overwrite or force
                f = PlanFile(step, unit, path, use.kind, overwrite, _exists(path, use.kind))
                problems += _problems(f, written.get(path.resolve()))
                if f.writes:
                    written[path.resolve()] = f
                found.append(f)
    return found, problems


def _problems(f: PlanFile, earlier: PlanFile | None) -> list[str]:
    on = f"{f.step.where()}, unit {f.unit}"
    if not f.writes:
        if earlier is None and not f.path.is_file():
            return [f"{on}: {f.path} does not exist (and no earlier step writes it)"]
        return []
    if earlier is not None and not f.overwrite:
        return [f"{on}: {f.path} is written already by {earlier.step.where()}, unit {earlier.unit}"]
    if f.exists and not f.overwrite:
        what = "has files in it" if f.kind == "tune report" else "exists"
        return [f"{on}: {f.path} {what}; say 'overwrite: true' (in the step or the plan) or pass --force"]
    return []


def report_problem(path: Path, *, force: bool) -> str | None:
    """Why the run's report may not be written at a path the user named (--report): its folder is missing or
    read-only, or it holds a file that is not a plan report (which each run replaces) and --force does not say to
    replace it."""
    if not path.parent.is_dir() or not os.access(path.parent, os.W_OK):
        return f"cannot write the report into {path.parent}: no such folder or not writable"
    if force or not path.exists():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        data = None
    if isinstance(data, dict) and {"status", "plan", "steps"} <= set(data):
        return None
    return f"{path} exists and is not a plan report; pass --force to replace it"
