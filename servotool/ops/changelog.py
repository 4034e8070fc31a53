"""The change log: the history of every value servotool changes on a drive (who, when, old -> new, EEPROM or RAM,
from which command), one line of JSON each, in a file per drive beside the automatic backups.

It is not the journal (ops.journal): a journal record holds what one live command is in the middle of, for the
next command to finish after a kill, and goes when the command ends; the log only grows, and is read by people.

What counts as a change (the one write path, ops.params.write_one and write_run, calls this module, so no writer
has to): each value a batch of lasting writes changed (ops.eeprom.persistence: param set, restore and its
rollback, param apply, a plan's set and save steps, tune's gains and their rollback, tune gains' trial levels),
with the memory it went to. Not counted: a motion's temporary settings (ops.eeprom.ram_writes: the JOG speed and
ramp, the hold's gains, the protections, all put back when the motion ends), the EEPROM switch flipped for a batch
and put back, a raised line (ops.boost), what journal recovery puts back, and a value written again unchanged to
store it. The drive's store function and its factory reset are one line each (`event`).

Appends are one write() of one line to a file opened for appending, made under the bus's write lock that every
batch holds (ops.journal.port_lock): processes on one bus take turns, and each bus has files of its own.
"""

from __future__ import annotations

import getpass
import json
import os
import re
import shlex
import socket
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from servotool.clock import utc_now
from servotool.drive import Drive, WriteResult
from servotool.errors import FileProblem, UsageError
from servotool.files import backup_dir
from servotool.model.codec import json_text, json_value
from servotool.model.profile import Entry
from servotool.model.quantity import quantity

MACHINE_ENV = "SERVOTOOL_MACHINE"
WHO_ENV = "SERVOTOOL_CHANGED_BY"
EEPROM, RAM = "EEPROM", "RAM"


def log_dir() -> Path:
    """Where the change logs are kept: beside the automatic backups, a folder per machine."""
    return backup_dir() / "changes"


# ----- who, from where, on which machine -------------------------------------------------------------------------


@dataclass(frozen=True)
class Origin:
    """Who makes the changes, from which command or playbook, on which machine (the name a fleet inventory or an
    Ansible host gives it; by default this computer's name)."""

    who: str
    source: str
    machine: str


def _default_origin() -> Origin:
    try:
        user = getpass.getuser()
    except (OSError, KeyError):  # no user name in the environment nor the password database (a bare container)
        user = str(os.getuid()) if hasattr(os, "getuid") else "unknown"
    host = socket.gethostname() or "localhost"
    argv = [Path(sys.argv[0]).name, *sys.argv[1:]] if sys.argv and sys.argv[0] else ["python"]
    if argv[0] in ("__main__.py", "main.py", "-m", "-c"):  # python -m servotool
        argv[0] = "servotool"
    return Origin(
        os.environ.get(WHO_ENV) or f"{user}@{host}",
        shlex.join(argv),
        os.environ.get(MACHINE_ENV) or host,
    )


_ORIGIN: ContextVar[Origin | None] = ContextVar("servotool_change_origin", default=None)


def current_origin() -> Origin:
    """The origin of the changes made now (this thread's, else the process's: its user, command line, host)."""
    return _ORIGIN.get() or _default_origin()


@contextmanager
def origin(*, who: str | None = None, source: str | None = None, machine: str | None = None) -> Iterator[Origin]:
    """Name who, from where and on which machine for the changes made inside (this thread only); what is not given
    stays as it was."""
    base = current_origin()
    found = replace(
        base,
        who=who or base.who,
        source=source or base.source,
        machine=machine_name(machine) if machine else base.machine,
    )
    token = _ORIGIN.set(found)
    try:
        yield found
    finally:
        _ORIGIN.reset(token)


def machine_name(name: str) -> str:
    """A machine name as a folder can hold it; UsageError for one that is empty or only dots."""
    cleaned = re.sub(r"[^A-Za-z0-9_.@-]+", "_", name.strip())
    if not cleaned.strip("._"):
        raise UsageError(f"bad machine name {name!r}: give letters, digits, '-', '_' or '.'")
    return cleaned


# ----- which writes are history ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Scope:
    key: tuple[str, int, str]
    memory: str | None  # EEPROM or RAM for a batch of lasting writes; None: temporary (a motion's settings)


_SCOPES: ContextVar[tuple[_Scope, ...]] = ContextVar("servotool_change_scopes", default=())


def _key(drive: Drive) -> tuple[str, int, str]:
    return (drive.port, drive.unit, drive.profile.id)


@contextmanager
def _scoped(drive: Drive, memory: str | None) -> Iterator[None]:
    token = _SCOPES.set((*_SCOPES.get(), _Scope(_key(drive), memory)))
    try:
        yield
    finally:
        _SCOPES.reset(token)


def lasting(drive: Drive, memory: str) -> Any:
    """The writes to this drive inside are meant to stay, in `memory` (EEPROM or RAM): each change is logged."""
    return _scoped(drive, memory)


def temporary(drive: Drive) -> Any:
    """The writes to this drive inside are a motion's settings, put back when it ends: not history."""
    return _scoped(drive, None)


def _memory(drive: Drive) -> str | None:
    """The memory the innermost scope of this drive writes to; None outside a lasting batch."""
    key = _key(drive)
    return next((s.memory for s in reversed(_SCOPES.get()) if s.key == key), None)


# ----- writing the log -------------------------------------------------------------------------------------------


def log_path(drive: Drive, machine: str | None = None) -> Path:
    """This drive's log: one per machine, bus, profile and unit (the bus named as the journal names it)."""
    from servotool.ops.journal import port_key

    profile = re.sub(r"[^A-Za-z0-9_.-]+", "_", drive.profile.id)
    bus = port_key(drive.port or "in-process")
    return log_dir() / (machine or current_origin().machine) / f"{bus}-{profile}-unit{drive.unit}.jsonl"


def before_write(drive: Drive, changes: list[tuple[Entry, int | None]]) -> list[int | None]:
    """Called by the write path before it writes: the old values (those not given are read, inside a lasting
    batch, so that the log can say old -> new), and the log proven writable first, so that a change is never made
    that the log cannot hold (FileProblem: nothing written)."""
    if _memory(drive) is None:
        return [old for _, old in changes]
    path = log_path(drive)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        os.close(os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644))
    except OSError as exc:
        raise FileProblem(path, f"cannot write the change log ({exc.strerror or exc}): nothing was written") from None
    unknown = [e for e, old in changes if old is None and e.readable]
    read = {r.entry.code: r.raw for r in drive.read_entries(unknown)} if unknown else {}
    return [old if old is not None else read.get(e.code) for e, old in changes]


def after_write(drive: Drive, results: list[WriteResult]) -> None:
    """Called by the write path once writes are verified: a line for each value a lasting batch changed."""
    memory = _memory(drive)
    if memory is None:
        return
    lines = [_change(drive, r, memory) for r in results if r.old != r.new]
    if lines:
        _append(drive, lines)


def event(drive: Drive, kind: str, **facts: Any) -> None:
    """A line for something the drive did as a whole at servotool's request: 'store' (its store function copied
    RAM to EEPROM), 'factory_reset' (its factory defaults, with the automatic backup taken before)."""
    _append(drive, [{**_head(drive), "event": kind, **facts}])


def _head(drive: Drive) -> dict[str, Any]:
    from servotool.ops.journal import drive_identity

    o = current_origin()
    return {
        "time": utc_now().isoformat(timespec="milliseconds").replace("+00:00", "Z"),
        "machine": o.machine,
        "who": o.who,
        "source": o.source,
        "bus": drive.port,
        "unit": drive.unit,
        "profile": drive.profile.id,
        "model": drive.profile.model,
        "identity": drive_identity(drive),
    }


def _change(drive: Drive, r: WriteResult, memory: str) -> dict[str, Any]:
    e = r.entry
    line: dict[str, Any] = {**_head(drive), "event": "change", "code": e.code, "name": e.name}
    for key, raw in (("old", r.old), ("new", r.new)):
        line[key] = None if raw is None else quantity(json_value(e, raw), e.unit)
    for key, raw in (("old", r.old), ("new", r.new)):
        if raw is not None and (text := json_text(e, raw)) is not None:
            line[f"{key}_text"] = text
    line.update({"old_raw": r.old, "new_raw": r.new, "memory": memory})
    return line


def _append(drive: Drive, lines: list[dict[str, Any]]) -> None:
    """Append lines in one write() to a file opened for appending (a concurrent appender's lines are never cut
    into ours); FileProblem when the log cannot be written (the writes it describes were made)."""
    path = log_path(drive)
    data = "".join(json.dumps(line, ensure_ascii=False, separators=(",", ":")) + "\n" for line in lines).encode()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise FileProblem(path, f"cannot write the change log ({exc.strerror or exc}); the drive WAS changed") from None


# ----- reading it ------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LogLine:
    """One line of a change log as read, with the file it came from."""

    data: dict[str, Any]
    path: Path


def read(
    *, machine: str | None = None, unit: int | None = None, profile: str | None = None, code: str | None = None
) -> tuple[list[LogLine], list[str]]:
    """Every line of every drive's log, oldest first, filtered by machine, unit, profile and entry code; and a
    note for each line that could not be read (a torn last line after a power loss, an edited file)."""
    root = log_dir()
    folders = [root / machine_name(machine)] if machine else sorted(p for p in _listing(root) if p.is_dir())
    found: list[LogLine] = []
    problems: list[str] = []
    for folder in folders:
        for path in sorted(p for p in _listing(folder) if p.suffix == ".jsonl"):
            found += _lines(path, problems)
    wanted = [
        line
        for line in found
        if (unit is None or line.data.get("unit") == unit)
        and (profile is None or line.data.get("profile") == profile)
        and (code is None or str(line.data.get("code", "")).upper() == code.upper())
    ]
    wanted.sort(key=lambda line: str(line.data.get("time", "")))
    return wanted, problems


def _listing(folder: Path) -> list[Path]:
    try:
        return list(folder.iterdir())
    except OSError:
        return []


def _lines(path: Path, problems: list[str]) -> list[LogLine]:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        problems.append(f"{path}: cannot read ({exc.strerror or exc})")
        return []
    out = []
    for number, row in enumerate(text.splitlines(), 1):
        if not row.strip():
            continue
        try:
            data = json.loads(row)
        except ValueError:
            problems.append(f"{path}: line {number} is not JSON (cut short?): left out")
            continue
        if isinstance(data, dict):
            out.append(LogLine(data, path))
        else:
            problems.append(f"{path}: line {number} is not an object: left out")
    return out
