"""Parameter backups: take, save, load and check, diff, restore with automatic backup and rollback, factory reset.

A backup is YAML: metadata, the raw value of every readable Pn (exact, as on the wire), the same values as text
for people, and a SHA-256 over the canonical content so an edited or damaged file is noticed.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import yaml

from servotool import __version__
from servotool.codec import format_value
from servotool.drive import Drive
from servotool.errors import DeviceError, ModbusException, ServoError, UsageError
from servotool.params import select
from servotool.profile import Entry, Profile

FORMAT = 1
IDENTITY_ROLES = ("firmware", "drive_type")
EFFECT_ORDER = {"immediate": 0, "unknown": 1, "servo_off": 2, "power_cycle": 3}


@dataclass
class Backup:
    profile: str
    profile_version: str
    model: str
    unit: int
    created: str
    tool_version: str
    identity: dict[str, str]
    values: dict[str, int]
    path: Path | None = None
    warnings: list[str] = field(default_factory=list)

    def checksum(self) -> str:
        canon = json.dumps({"profile": self.profile, "model": self.model, "unit": self.unit,
                            "values": dict(sorted(self.values.items()))}, sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(canon.encode()).hexdigest()

    def to_yaml(self, profile: Profile) -> str:
        text = {code: format_value(profile.entry(code), raw) + (f" {profile.entry(code).unit}"
                                                                 if profile.entry(code).unit else "")
                for code, raw in self.values.items()}
        doc = {"servotool_backup": FORMAT, "profile": self.profile, "profile_version": self.profile_version,
               "model": self.model, "unit": self.unit, "created": self.created, "tool_version": self.tool_version,
               "identity": self.identity, "checksum": self.checksum(), "values": self.values, "display": text}
        return "# servotool parameter backup; values are raw register integers, 'display' is for reading only\n" + \
            yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def backup_dir() -> Path:
    """Where automatic backups go (SERVOTOOL_BACKUP_DIR, else the XDG data dir)."""
    if env := os.environ.get("SERVOTOOL_BACKUP_DIR"):
        return Path(env)
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "servotool" / "backups"


def take(drive: Drive, progress: Callable[[int], None] | None = None) -> Backup:
    """Read every readable Pn (coalesced) and the identity entries."""
    p = drive.profile
    entries = select(p)
    readings = drive.read_entries(entries, progress=progress)
    identity: dict[str, str] = {}
    ident = [e for e in (p.role(r) for r in IDENTITY_ROLES) if e is not None and e.readable]
    for r in drive.read_entries(ident) if ident else []:
        identity[r.entry.code] = r.text
    return Backup(p.id, p.version, p.model, drive.unit, datetime.now(UTC).isoformat(timespec="seconds"),
                  __version__, identity, {r.entry.code: r.raw for r in readings})


def save(backup: Backup, profile: Profile, path: Path, *, force: bool = False) -> Path:
    """Write atomically (temp file + rename); never replace an existing file unless forced."""
    if path.exists() and not force:
        raise UsageError(f"{path} exists; choose another name or pass --force to replace it")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}", suffix=".tmp")
    except OSError as exc:
        raise ServoError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(backup.to_yaml(profile))
            fh.flush()
            os.fsync(fh.fileno())
        if force:
            os.replace(tmp, path)
        else:
            # link() fails if the name appeared since the check above, so nothing on disk is ever replaced.
            os.link(tmp, path)
    except FileExistsError:
        raise UsageError(f"{path} exists; choose another name or pass --force to replace it") from None
    except OSError as exc:
        raise ServoError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        Path(tmp).unlink(missing_ok=True)
    backup.path = path
    return path


def write_backup(drive: Drive, path: Path, *, force: bool = False,
                 progress: Callable[[int], None] | None = None) -> Path:
    return save(take(drive, progress), drive.profile, path, force=force)


def _auto_path(drive: Drive, reason: str) -> Path:
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S%fZ")
    return backup_dir() / f"{drive.profile.id}-unit{drive.unit}-{stamp}-{reason}.yaml"


def auto_backup(drive: Drive, reason: str) -> Path:
    """Save the drive's current state under backup_dir() (never replacing a file)."""
    return write_backup(drive, _auto_path(drive, reason))


def load(path: Path, profile: Profile, *, force: bool = False) -> Backup:
    """Read and check a backup against the profile; every problem is a one-line UsageError, before any write."""
    what = str(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UsageError(f"cannot read {what}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise UsageError(f"{what}: not a servotool backup file (not UTF-8 text)") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise UsageError(f"{what}: not a valid backup (broken YAML{f' at line {mark.line + 1}' if mark else ''})") \
            from None
    if not isinstance(data, dict) or data.get("servotool_backup") != FORMAT:
        raise UsageError(f"{what}: not a servotool backup file (format {FORMAT})")
    for key, kind in (("profile", str), ("model", str), ("unit", int), ("values", dict), ("checksum", str)):
        if not isinstance(data.get(key), kind) or isinstance(data.get(key), bool):
            raise UsageError(f"{what}: '{key}' is missing or of the wrong type (truncated or edited file?)")
    display = data.get("display")
    if not isinstance(display, dict) or set(map(str, display)) != set(map(str, data["values"])):
        raise UsageError(f"{what}: the file is incomplete (truncated?): its value and display sections differ")
    warnings = []
    if data["model"] != profile.model or data["profile"] != profile.id:
        msg = f"{what}: backup of a {data['model']} ({data['profile']}), not of this {profile.model} ({profile.id})"
        if not force:
            raise UsageError(msg + "; --force to restore anyway")
        warnings.append(msg)
    values: dict[str, int] = {}
    for code, raw in data["values"].items():
        entry = profile.find(str(code))
        if entry is None or entry.cls != "Pn":
            raise UsageError(f"{what}: unknown parameter {code} for profile {profile.id}")
        if not isinstance(raw, int) or isinstance(raw, bool):
            raise UsageError(f"{what}: {code}: value {raw!r} is not an integer")
        if not entry.min <= raw <= entry.max:
            raise UsageError(f"{what}: {code}: value {raw} is outside {entry.min}..{entry.max}")
        values[entry.code] = raw
    b = Backup(data["profile"], str(data.get("profile_version", "")), data["model"], data["unit"],
               str(data.get("created", "")), str(data.get("tool_version", "")),
               {str(k): str(v) for k, v in (data.get("identity") or {}).items()}, values, path, warnings)
    if b.checksum() != data["checksum"]:
        msg = f"{what}: checksum mismatch: the values were edited or damaged"
        if not force:
            raise UsageError(msg + "; --force to use it anyway")
        warnings.append(msg)
    return b


@dataclass(frozen=True)
class Difference:
    entry: Entry
    a: int | None
    b: int | None

    def as_json(self) -> dict[str, Any]:
        e = self.entry
        return {"code": e.code, "name": e.name, "unit": e.unit, "effect": e.effect,
                "a": None if self.a is None else format_value(e, self.a),
                "b": None if self.b is None else format_value(e, self.b)}


def diff(profile: Profile, a: dict[str, int], b: dict[str, int]) -> list[Difference]:
    out = []
    for e in profile.of_class("Pn"):
        va, vb = a.get(e.code), b.get(e.code)
        if (va is not None or vb is not None) and va != vb:
            out.append(Difference(e, va, vb))
    return out


def defaults(profile: Profile) -> dict[str, int]:
    return {e.code: e.default for e in profile.of_class("Pn") if e.default is not None}


@dataclass
class RestorePlan:
    changes: list[tuple[Entry, int, int]]       # entry, current, target (in write order)
    skipped: list[tuple[Entry, str]]

    @property
    def needs_power_cycle(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "power_cycle"]

    @property
    def needs_servo_off(self) -> list[Entry]:
        return [e for e, _, _ in self.changes if e.effect == "servo_off"]


def plan_restore(profile: Profile, backup: Backup, current: dict[str, int], *, only: str | None = None,
                 include: list[str] | None = None) -> RestorePlan:
    """Only entries that differ; axis-specific (copy: false) ones only when named; immediate ones first."""
    named = {profile.entry(c).code for c in include or []}
    if only is not None and only not in {e.group for e in profile.entries}:
        raise UsageError(f"unknown group '{only}' for profile {profile.id}")
    changes, skipped = [], []
    for code, target in backup.values.items():
        e = profile.entry(code)
        if only is not None and e.group != only and e.code not in named:
            continue
        if not e.writable:
            continue
        if profile.persistence.is_switch(e.code):
            # Writing it would change where every later value goes; the restore sets it for its own writes.
            if current.get(code) != target:
                skipped.append((e, "EEPROM write switch: the restore sets it for its writes and leaves it as it was"))
            continue
        if not e.copy and e.code not in named:
            if current.get(code) != target:
                skipped.append((e, "axis-specific (name it with --include to restore)"))
            continue
        if current.get(code) != target:
            changes.append((e, current[code], target))
    changes.sort(key=lambda c: EFFECT_ORDER.get(c[0].effect, 1))
    return RestorePlan(changes, skipped)


@dataclass
class RestoreReport:
    auto_backup: Path
    written: list[Entry]
    plan: RestorePlan
    persisted: bool = True      # False: the drive keeps the values in RAM only (lost at power-off)


class RestoreFailed(ServoError):
    """A write failed midway; the message says exactly what state the drive is in.

    The exit code is the cause's: 1 when the drive or link refused, 3 when a value did not read back.
    """

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code


Notice = Callable[[str], None]


def check_servo_off(drive: Drive, entries: list[Entry], what: str) -> None:
    """Refuse before any write when entries that may only change with the servo off meet a running servo."""
    from servotool.motion import servo_is_on

    if entries and servo_is_on(drive):
        codes = ", ".join(e.code for e in entries[:6]) + (" ..." if len(entries) > 6 else "")
        raise UsageError(f"{what} changes {codes}, which the drive accepts only with the servo off: "
                         f"switch the servo off first")


def restore(drive: Drive, backup: Backup, plan: RestorePlan,
            progress: Callable[[Entry], None] | None = None, notice: Notice | None = None) -> RestoreReport:
    """Automatic backup first, then write and verify each change; on failure, roll back what was changed."""
    from servotool.params import persistence, write_one

    check_servo_off(drive, plan.needs_servo_off, "the restore")
    before = take(drive)
    auto = save(before, drive.profile, _auto_path(drive, "before-restore"))
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    done: list[Entry] = []
    # A backup holds the drive's stored settings, so the restored values (and any rollback) go to EEPROM the
    # way the profile says: at once, by flipping a RAM/EEPROM switch for the batch, or by one save at the end.
    with persistence(drive, save=True) as kept:
        for entry, old, new in plan.changes:
            try:
                write_one(drive, entry, new, before.values.get(entry.code, old))
            except ServoError as exc:
                # The failed entry too: a write that did not read back may still have changed it.
                state = _roll_back(drive, [*done, entry], before.values, auto)
                raise RestoreFailed(f"restore stopped at {entry.code}: {exc}; {state}", exc.exit_code) from None
            done.append(entry)
            if progress:
                progress(entry)
    return RestoreReport(auto, done, plan, kept["persisted"])


def _roll_back(drive: Drive, touched: list[Entry], snapshot: dict[str, int], auto: Path) -> str:
    """Put touched entries back to the snapshot, newest first, then say how the whole drive compares to it."""
    from servotool.params import write_one

    undo_failed: list[str] = []
    for e in reversed(touched):
        try:
            now = drive.read_entries([e])[0].raw
            if now != snapshot[e.code]:
                write_one(drive, e, snapshot[e.code], now)
        except ServoError as again:
            undo_failed.append(f"{e.code} ({again})")
            if isinstance(again, DeviceError) and not isinstance(again, ModbusException):
                break                        # no answer at all: every further attempt would time out too
    try:
        after = {r.entry.code: r.raw for r in drive.read_entries(select(drive.profile))}
    except ServoError as exc:
        return (f"the drive no longer answers ({exc}), so its state is unknown: when it does, compare it with "
                f"'servotool param diff {auto}' and restore that file if needed")
    # The EEPROM switch is flipped for the batch on purpose (and put back when it ends): not a difference.
    differ = [code for code, raw in snapshot.items()
              if after.get(code) != raw and not drive.profile.persistence.is_switch(code)]
    if not differ:
        return (f"rolled back {len(touched) - 1} written entries; read back, the drive equals the automatic "
                f"backup {auto}")
    shown = ", ".join(f"{c} is {format_value(drive.profile.entry(c), after[c])}, was "
                      f"{format_value(drive.profile.entry(c), snapshot[c])}" for c in differ[:6])
    more = f" and {len(differ) - 6} more" if len(differ) > 6 else ""
    why = f" (could not undo {'; '.join(undo_failed)})" if undo_failed else ""
    return (f"rollback incomplete{why}: {len(differ)} entries differ from the automatic backup {auto}: {shown}{more}; "
            f"run 'servotool param restore {auto}' once the cause is fixed")


def restore_file(drive: Drive, path: Path, notice: Notice | None = None) -> str:
    """Plan step: restore a backup file completely (no prompts)."""
    b = load(path, drive.profile)
    current = {r.entry.code: r.raw for r in drive.read_entries(select(drive.profile))}
    rplan = plan_restore(drive.profile, b, current)
    if not rplan.changes:
        return "nothing to restore: the drive already matches"
    report = restore(drive, b, rplan, notice=notice)
    return f"{len(report.written)} entries restored (automatic backup {report.auto_backup})"


def factory_reset(drive: Drive, notice: Notice | None = None) -> Path:
    """Automatic backup, then the profile's factory-reset function."""
    drive.profile.need_role("factory_reset", "param reset")
    check_servo_off(drive, [e for e in drive.profile.of_class("Pn") if e.effect == "servo_off"], "a factory reset")
    auto = auto_backup(drive, "before-reset")
    if notice:
        notice(f"automatic backup of the drive's current state: {auto}")
    drive.trigger("factory_reset", "param reset")
    return auto


def not_at_default(drive: Drive) -> list[tuple[Entry, int]]:
    """Readable parameters whose value differs from the profile's factory default (entry, raw)."""
    return [(r.entry, r.raw) for r in drive.read_entries(select(drive.profile))
            if r.entry.default is not None and r.raw != r.entry.default]
