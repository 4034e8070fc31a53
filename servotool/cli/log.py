"""`servotool log`: the change log (ops.changelog), every value servotool changed, per drive or machine."""

from __future__ import annotations

from typing import Any

import typer

from servotool.cli.common import JSON_OPT
from servotool.cli.render import emit_json, out, table, warn
from servotool.words import count

EVENTS = {"store": "stored in EEPROM", "factory_reset": "factory reset"}


def log(
    unit: int = typer.Option(None, "--unit", "-u", help="Only this unit id."),
    machine: str = typer.Option(None, "--machine", "-m", help="Only this machine (default: every machine's log)."),
    code: str = typer.Option(None, "--code", help="Only changes of this entry (e.g. Po101)."),
    last: int = typer.Option(None, "--last", help="Only the last N lines."),
    as_json: bool = JSON_OPT,
) -> None:
    """Every value servotool changed, oldest first: when, who, from which command, old -> new, EEPROM or RAM.

    The log is kept beside the automatic backups (SERVOTOOL_BACKUP_DIR/changes/MACHINE/, one JSON line per change,
    a file per drive); a machine is named by SERVOTOOL_MACHINE, a fleet inventory or an Ansible task, else by this
    computer's name.
    """
    from servotool.errors import UsageError
    from servotool.ops import changelog

    if last is not None and last < 1:
        raise UsageError(f"--last {last}: give 1 or more")
    found, problems = changelog.read(machine=machine, unit=unit, code=code)
    for problem in problems:
        warn(problem)
    rows = [line.data for line in found][-last if last else None :]
    if as_json:
        emit_json(rows)
        return
    if not rows:
        where = (f" of machine {machine}" if machine else "") + (f" for unit {unit}" if unit else "")
        out.print(f"no changes logged{where} ({changelog.log_dir()})", markup=False)
        return
    t = table("Time", "Machine", "Unit", "Code", "Old", "New", "Memory", "Who", "Source")
    for row in rows:
        t.add_row(*_cells(row))
    out.print(t)
    out.print(f"{count(len(rows), 'change')} ({changelog.log_dir()})", markup=False)


def _cells(row: dict[str, Any]) -> list[str]:
    when = str(row.get("time", ""))[:19].replace("T", " ")
    drive = f"{row.get('unit', '')} {row.get('model', '')}".strip()
    if row.get("event") != "change":
        what = EVENTS.get(str(row.get("event")), str(row.get("event")))
        return [when, str(row.get("machine", "")), drive, what, "", "", str(row.get("memory", "")), *_by(row)]
    return [
        when,
        str(row.get("machine", "")),
        drive,
        str(row.get("code", "")),
        _value(row, "old"),
        _value(row, "new"),
        str(row.get("memory", "")),
        *_by(row),
    ]


def _value(row: dict[str, Any], key: str) -> str:
    if (text := row.get(f"{key}_text")) is not None:
        return str(text)
    q = row.get(key)
    if not isinstance(q, dict):
        return ""
    return f"{q.get('value')} {q.get('unit') or ''}".strip()


def _by(row: dict[str, Any]) -> list[str]:
    return [str(row.get("who", "")), str(row.get("source", ""))]
