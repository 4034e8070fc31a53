"""Parameter operations built on Drive: select, read, validate-then-write many entries."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.drive import Drive, Reading, WriteResult
from servotool.errors import UsageError
from servotool.profile import Entry, Profile


def select(profile: Profile, *, group: str | None = None, classes: tuple[str, ...] = ("Pn",)) -> list[Entry]:
    """Readable entries of the given classes (and group), in profile order."""
    if group is not None and group not in {e.group for e in profile.entries}:
        known = ", ".join(sorted({e.group for e in profile.entries if e.group}))
        raise UsageError(f"unknown group '{group}' for profile {profile.id} (groups: {known})")
    return [e for e in profile.entries
            if e.cls in classes and e.readable and (group is None or e.group == group)]


@dataclass(frozen=True)
class SetPlan:
    """Validated assignments with the drive's current values."""

    changes: list[tuple[Entry, int, int]]  # entry, old raw, new raw
    unchanged: list[tuple[Entry, int]]


def plan_set(drive: Drive, assignments: list[str], *, raw: bool = False) -> SetPlan:
    """Parse and range-check every CODE=VALUE, then read current values; nothing is written."""
    if not assignments:
        raise UsageError("nothing to set: give CODE=VALUE ...")
    parsed: list[tuple[Entry, str]] = []
    seen: set[str] = set()
    for text in assignments:
        entry, _ = drive.parse_assignment(text, raw=raw)  # validates code/access/type/range before any I/O
        if entry.code in seen:
            raise UsageError(f"{entry.code} is given twice")
        seen.add(entry.code)
        parsed.append((entry, text.partition("=")[2]))
    current = {r.entry.code: r.raw for r in drive.read_entries([e for e, _ in parsed if e.readable])}
    changes: list[tuple[Entry, int, int]] = []
    unchanged: list[tuple[Entry, int]] = []
    for entry, value in parsed:
        old = current.get(entry.code)
        # Digit-field input like 'X=0' is relative to the current value, so parse again with it.
        new = drive.parse_assignment(f"{entry.code}={value}", raw=raw, current=old)[1]
        if old == new:
            unchanged.append((entry, new))
        else:
            changes.append((entry, old if old is not None else new, new))
    return SetPlan(changes, unchanged)


def write_one(drive: Drive, entry: Entry, raw: int, old: int | None = None) -> WriteResult:
    """The one path every parameter write takes (set, restore, plans): write, then verify by read-back."""
    return drive.write_verified(entry, raw, old)


def apply_set(drive: Drive, plan: SetPlan) -> list[WriteResult]:
    """Write the planned changes in order, each verified by read-back."""
    return [write_one(drive, entry, new, old) for entry, old, new in plan.changes]


def read_all(drive: Drive, entries: list[Entry]) -> list[Reading]:
    return drive.read_entries(entries)
