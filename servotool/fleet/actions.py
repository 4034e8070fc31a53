"""What `fleet backup`, `fleet drift` and `fleet apply` do on each drive, on the library's functions: snapshots
(ops.backup), the one apply function (ops.apply) and desired sets (ops.desired)."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.fleet.inventory import BusSpec, Target
from servotool.model.codec import format_value
from servotool.ops.apply import ApplyResult

SAVED, SAME = "saved", "unchanged"
EQUAL, DIFFERS = "equal", "differs"
SHOWN = 3  # changes named in a table's line; --json has them all


def snapshot_path(out: Path, spec: BusSpec, unit: int, profile: str) -> Path:
    """Where `fleet backup` keeps a drive's snapshot: OUT/MACHINE/BUS-unitN-PROFILE.yaml, the same path each time,
    so that a folder under version control shows each drive's changes."""
    return out / spec.machine / f"{spec.name}-unit{unit}-{profile}.yaml"


def _boost(drives: list[Drive], spec: BusSpec, notice: Callable[[str], None], what: str) -> AbstractContextManager[Any]:
    """The line raised for a long read as `param backup` raises it (the bus's boost option; by default only where
    no other device answers), for all of the bus's drives at once."""
    from servotool.ops.boost import line_boost

    return line_boost(drives, spec.options.boost, sole=spec.port == "sim", notice=notice, what=what)


@dataclass
class Backup:
    """A snapshot of each drive into OUT (replaced in place: 'saved' when it changed, 'unchanged' when not)."""

    out: Path
    name: str = "backup"

    def on_bus(self, drives: list[Drive], spec: BusSpec, notice: Callable[[str], None]) -> AbstractContextManager[Any]:
        return _boost(drives, spec, notice, "the backup")

    def on_drive(self, drive: Drive, target: Target, spec: BusSpec) -> tuple[str, str, dict[str, Any]]:
        from servotool.errors import ServoError
        from servotool.files import write_atomic
        from servotool.ops import backup

        taken = backup.take(drive)
        taken.machine = spec.machine
        text = taken.to_snapshot(drive.profile)
        path = snapshot_path(self.out, spec, drive.unit, drive.profile.id)
        try:
            same = path.read_text(encoding="utf-8") == text
        except (OSError, UnicodeDecodeError):
            same = False
        if not same:
            try:
                write_atomic(path, text)
            except OSError as exc:
                raise ServoError(f"cannot write {path}: {exc.strerror or exc}") from None
        status = SAME if same else SAVED
        lacking = f", {len(taken.missing)} not on this drive" if taken.missing else ""
        facts = {"file": str(path), "entries": len(taken.values), "identity": taken.identity, "missing": taken.missing}
        return status, f"{path} ({len(taken.values)} parameters{lacking})", facts


def _desired(drive: Drive, target: Target, against: Path | None, spec: BusSpec) -> Any:
    """The drive's golden set: its snapshot in `against` (a folder `fleet backup` wrote), else its golden file."""
    from servotool.ops import desired

    golden = snapshot_path(against, spec, drive.unit, drive.profile.id) if against is not None else target.golden
    if golden is None:
        raise UsageError("no golden file for this drive: give 'golden:' in the inventory (or --against DIR)")
    if not golden.exists():
        raise UsageError(f"golden file {golden} does not exist")
    wanted = desired.load(golden, drive.profile)
    if not wanted.from_backup and wanted.unit is not None and wanted.unit != drive.unit:
        raise UsageError(f"{golden} is for unit {wanted.unit}, not unit {drive.unit}")
    return wanted


def _changes(result: ApplyResult) -> str:
    parts = [
        f"{s.entry.code} {format_value(s.entry, s.before)} -> {format_value(s.entry, s.desired)}"
        + (f" {s.entry.unit}" if s.entry.unit else "")
        for s in result.changes[:SHOWN]
    ]
    more = len(result.changes) - SHOWN
    return ", ".join(parts) + (f" and {more} more" if more > 0 else "")


@dataclass
class Drift:
    """Each drive against its golden file (or its snapshot in a folder): 'equal' or 'differs', nothing written."""

    against: Path | None = None
    name: str = "drift"

    def on_bus(self, drives: list[Drive], spec: BusSpec, notice: Callable[[str], None]) -> AbstractContextManager[Any]:
        return _boost(drives, spec, notice, "the comparison")

    def on_drive(self, drive: Drive, target: Target, spec: BusSpec) -> tuple[str, str, dict[str, Any]]:
        from servotool.ops.apply import apply

        wanted = _desired(drive, target, self.against, spec)
        result = apply(drive, wanted, check=True)
        facts = {"golden": wanted.source, **result.as_json()}
        if not result.changes:
            return EQUAL, f"as {wanted.source} ({len(result.settings)} parameters)", facts
        return DIFFERS, _changes(result), facts


@dataclass
class Apply:
    """Each drive brought to its golden file (check: only said): changed, unchanged or would change."""

    check: bool = False
    name: str = "apply"

    def on_bus(self, drives: list[Drive], spec: BusSpec, notice: Callable[[str], None]) -> AbstractContextManager[Any]:
        return nullcontext()

    def on_drive(self, drive: Drive, target: Target, spec: BusSpec) -> tuple[str, str, dict[str, Any]]:
        from servotool.ops.apply import apply

        wanted = _desired(drive, target, None, spec)
        result = apply(drive, wanted, check=self.check)
        facts = {"golden": wanted.source, **result.as_json()}
        detail = _changes(result) if result.changes else f"as {wanted.source} ({len(result.settings)} parameters)"
        return result.status, detail, facts
