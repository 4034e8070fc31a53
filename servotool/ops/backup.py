"""Parameter backups: the file format, taking one from a drive, saving, loading and diffing."""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool import __version__
from servotool.clock import utc_now
from servotool.drive import Drive
from servotool.errors import ServoError, UsageError
from servotool.files import backup_dir, load_yaml, write_atomic
from servotool.model.codec import format_value, json_text, json_value
from servotool.model.identity import identity_entries
from servotool.model.profile import Entry, Profile
from servotool.ops import backup_csv
from servotool.ops.params import read_settings, select

FORMAT = 1


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
    missing: list[str] = field(default_factory=list)  # Pn entries the drive lacks (not in values)
    machine: str = ""  # the machine a snapshot names (a fleet inventory's or an Ansible host's name)
    snapshot: bool = False  # read from a snapshot (to_snapshot): no time stamp, no checksum

    def checksum(self) -> str:
        canon = json.dumps(
            {
                "profile": self.profile,
                "model": self.model,
                "unit": self.unit,
                "values": dict(sorted(self.values.items())),
            },
            sort_keys=True,
            separators=(",", ":"),
        )
        return hashlib.sha256(canon.encode()).hexdigest()

    def sorted_values(self, profile: Profile) -> dict[str, int]:
        """The values in register-address order (then code): the same order in every file of a drive."""
        return dict(sorted(self.values.items(), key=lambda item: (profile.entry(item[0]).address, item[0])))

    def to_yaml(self, profile: Profile) -> str:
        values = self.sorted_values(profile)
        text = {code: _display(profile.entry(code), raw) for code, raw in values.items()}
        doc = {
            "servotool_backup": FORMAT,
            "profile": self.profile,
            "profile_version": self.profile_version,
            "model": self.model,
            "unit": self.unit,
            "created": self.created,
            "tool_version": self.tool_version,
            "identity": self.identity,
            "checksum": self.checksum(),
            "values": values,
            "display": text,
        }
        if self.missing:
            doc["missing"] = {code: "not on this drive" for code in sorted(self.missing)}
        return (
            "# servotool parameter backup; values are raw register integers, 'display' is for reading only\n"
            + _dump(doc)
        )

    def to_snapshot(self, profile: Profile) -> str:
        """The backup as a snapshot for version control: keyed by the drive (profile, model, unit, machine and its
        identity entries, firmware among them), no time stamp, tool version or checksum, one line per value in
        address order with its reading as a comment, so that a diff of two snapshots of a drive shows only the
        values that changed. The last key, `complete`, tells a whole file from a truncated one."""
        head: dict[str, Any] = {
            "servotool_backup": FORMAT,
            "snapshot": True,
            "profile": self.profile,
            "profile_version": self.profile_version,
            "model": self.model,
            "unit": self.unit,
        }
        if self.machine:
            head["machine"] = self.machine
        head["identity"] = self.identity
        rows = []
        for code, raw in self.sorted_values(profile).items():
            key = _dump({code: raw}).rstrip("\n")
            rows.append(f"  {key}  # {_display(profile.entry(code), raw)}".rstrip() + "\n")
        tail = {"missing": {code: "not on this drive" for code in sorted(self.missing)}} if self.missing else {}
        on = f" on {self.machine}" if self.machine else ""
        return (
            f"# servotool snapshot of {self.model} unit {self.unit}{on}: raw register values, each with its reading "
            "as a comment;\n# no time stamp, so that two snapshots of a drive differ only where its settings do\n"
            + _dump(head)
            + ("values:\n" + "".join(rows) if rows else "values: {}\n")
            + (_dump(tail) if tail else "")
            + "complete: true\n"
        )


def _display(entry: Entry, raw: int) -> str:
    """A value as a backup shows it for reading: the manual's form and the unit ('25.0 Hz', 'd 1 21')."""
    return format_value(entry, raw) + (f" {entry.unit}" if entry.unit else "")


def _dump(doc: dict[str, Any]) -> str:
    import yaml  # only where a backup is written: `param get` starts without PyYAML

    return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)


def take(drive: Drive, progress: Callable[[int], None] | None = None) -> Backup:
    """Read every readable Pn (coalesced) and the entries of the profile's identity section; entries the drive
    lacks are left out and listed in `missing` (Pn only)."""
    p = drive.profile
    values = read_settings(drive, progress)
    identity: dict[str, str] = {}
    ident = identity_entries(p)
    for r in drive.read_entries(ident, partial=True) if ident else []:
        identity[r.entry.code] = r.text
    return Backup(
        p.id,
        p.version,
        p.model,
        drive.unit,
        utc_now().isoformat(timespec="seconds"),
        __version__,
        identity,
        values,
        missing=[e.code for e in select(p) if e.code in drive.missing],
    )


def check_output(path: Path, *, force: bool = False) -> None:
    """Refuse, before any drive I/O, an output the save would refuse after reading the whole drive: an existing
    file without --force, a folder that is missing or not writable, a name that looks like an option."""
    if str(path).startswith("-"):
        raise UsageError(f"'{path}' looks like an option, not a file name (write ./{path} for such a file)")
    if path.exists() and not force:
        raise UsageError(f"{path} exists; choose another name or pass --force to replace it")
    if path.is_dir():
        raise UsageError(f"{path} is a folder; give a file name")
    folder = path.parent
    if not folder.is_dir():
        raise UsageError(f"cannot write {path}: no folder {folder}")
    if not os.access(folder, os.W_OK):
        raise UsageError(f"cannot write {path}: the folder {folder} is not writable")


def save(backup: Backup, profile: Profile, path: Path, *, force: bool = False, fmt: str = "yaml") -> Path:
    """Write atomically (YAML, with fmt="snapshot" a snapshot for version control, or with fmt="csv" a table for a
    spreadsheet); never replace an existing file unless forced."""
    exists = UsageError(f"{path} exists; choose another name or pass --force to replace it")
    if path.exists() and not force:
        raise exists
    meta = {
        "profile": backup.profile,
        "model": backup.model,
        "unit": str(backup.unit),
        "created": backup.created,
        "tool_version": backup.tool_version,
    }
    if fmt == "csv":
        text = backup_csv.to_csv(profile, meta, backup.sorted_values(profile))
    else:
        text = backup.to_snapshot(profile) if fmt == "snapshot" else backup.to_yaml(profile)
    try:
        write_atomic(path, text, replace=force)
    except FileExistsError:
        raise exists from None
    except OSError as exc:
        raise ServoError(f"cannot write {path}: {exc.strerror or exc}") from None
    backup.path = path
    return path


def write_backup(
    drive: Drive, path: Path, *, force: bool = False, progress: Callable[[int], None] | None = None
) -> Path:
    return save(take(drive, progress), drive.profile, path, force=force)


def auto_path(drive: Drive, reason: str) -> Path:
    """A new file name under backup_dir() for an automatic backup taken for a reason ('before-restore')."""
    stamp = utc_now().strftime("%Y%m%dT%H%M%S%fZ")
    return backup_dir() / f"{drive.profile.id}-unit{drive.unit}-{stamp}-{reason}.yaml"


def auto_backup(drive: Drive, reason: str, progress: Callable[[int], None] | None = None) -> Path:
    """Save the drive's current state under backup_dir() (never replacing a file)."""
    return write_backup(drive, auto_path(drive, reason), progress=progress)


def load(path: Path, profile: Profile, *, force: bool = False) -> Backup:
    """Read and check a backup (YAML, or CSV from a spreadsheet) against the profile; every problem is a one-line
    UsageError, before any write."""
    if path.suffix.lower() == ".csv":
        meta, values, warnings = backup_csv.read(path, profile, force=force)
        unit = meta.get("unit", "")
        return Backup(
            meta.get("profile", ""),
            "",
            meta.get("model", ""),
            int(unit) if unit.isdigit() else 0,
            meta.get("created", ""),
            meta.get("tool_version", ""),
            {},
            values,
            path,
            warnings,
        )
    what = str(path)
    data = load_yaml(path)
    if not isinstance(data, dict) or data.get("servotool_backup") != FORMAT:
        raise UsageError(f"{what}: not a servotool backup file (format {FORMAT})")
    snapshot = data.get("snapshot") is True
    needed = (("profile", str), ("model", str), ("unit", int), ("values", dict))
    for key, kind in (*needed, *((("checksum", str),) if not snapshot else ())):
        if not isinstance(data.get(key), kind) or isinstance(data.get(key), bool):
            raise UsageError(f"{what}: '{key}' is missing or of the wrong type (truncated or edited file?)")
    if snapshot:
        if data.get("complete") is not True:
            raise UsageError(f"{what}: the snapshot is incomplete (truncated?): it does not end with 'complete: true'")
    else:
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
    missing = data.get("missing") or {}
    if not isinstance(missing, dict) or any(profile.find(str(c)) is None for c in missing):
        raise UsageError(f"{what}: 'missing' must map this profile's codes to a note")
    b = Backup(
        data["profile"],
        str(data.get("profile_version", "")),
        data["model"],
        data["unit"],
        str(data.get("created", "")),
        str(data.get("tool_version", "")),
        {str(k): str(v) for k, v in (data.get("identity") or {}).items()},
        values,
        path,
        warnings,
        [profile.entry(str(c)).code for c in missing],
        str(data.get("machine", "")),
        snapshot,
    )
    if not snapshot and b.checksum() != data["checksum"]:
        msg = f"{what}: checksum mismatch: the values were edited or damaged"
        if not force:
            raise UsageError(msg + "; --force to use it anyway")
        warnings.append(msg)
    return b


def profile_of(path: Path) -> str | None:
    """The profile id a backup file names, or None when the file does not say (not a backup)."""
    if path.suffix.lower() == ".csv":
        return backup_csv.profile_of(path)
    data = load_yaml(path)
    return data.get("profile") if isinstance(data, dict) and isinstance(data.get("profile"), str) else None


@dataclass(frozen=True)
class Difference:
    entry: Entry
    a: int | None
    b: int | None

    def as_json(self) -> dict[str, Any]:
        e = self.entry
        out: dict[str, Any] = {
            "code": e.code,
            "name": e.name,
            "unit": e.unit,
            "effect": e.effect,
            "a": None if self.a is None else json_value(e, self.a),
            "b": None if self.b is None else json_value(e, self.b),
        }
        for key, raw in (("a", self.a), ("b", self.b)):  # an encoded value's manual form beside its number
            if raw is not None and (text := json_text(e, raw)) is not None:
                out[f"{key}_text"] = text
        for key, raw in (("a", self.a), ("b", self.b)):
            if raw is not None and raw in e.enum:
                out[f"{key}_meaning"] = e.enum[raw]
        return out


def diff(profile: Profile, a: dict[str, int], b: dict[str, int]) -> list[Difference]:
    out = []
    for e in profile.of_class("Pn"):
        va, vb = a.get(e.code), b.get(e.code)
        if (va is not None or vb is not None) and va != vb:
            out.append(Difference(e, va, vb))
    return out


def defaults(profile: Profile) -> dict[str, int]:
    return {e.code: e.default for e in profile.of_class("Pn") if e.default is not None}
