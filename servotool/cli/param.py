"""`servotool param ...`: read, set and list parameters."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import typer

from servotool.cli import complete
from servotool.cli.common import JSON_OPT, drive, state
from servotool.cli.render import emit_json, info, out, progress, table, warn
from servotool.cli.values import footnote, json_mark, spoken, texts, unit_text
from servotool.connection import resolve
from servotool.drive import Reading
from servotool.errors import UnknownName
from servotool.model.codec import format_field, format_value, get_field, json_text, json_value, split_field
from servotool.model.lookup import class_name, search, suggest
from servotool.words import count

if TYPE_CHECKING:
    from servotool.model.profile import Profile

app = typer.Typer(help="Read, set and list drive parameters.")


@app.command("get")
def get(
    ctx: typer.Context,
    codes: list[str] = typer.Argument(
        ...,
        autocompletion=complete.codes,
        help="Vendor codes (e.g. Pn004, Po109, H09-06), role names, or "
        "CODE.FIELD for one field of a two-/four-parameter value (e.g. Po001.Y).",
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Read entries (any class) from the drive."""
    with drive(ctx) as d:
        targets = [split_field(d.profile, c) for c in codes]
        readings = d.read_entries([e for e, _ in targets])
    if as_json:
        emit_json(
            [
                _reading_json(d.profile, r) if f is None else _field_json(r, f)
                for r, (_, f) in zip(readings, targets, strict=True)
            ]
        )
        return
    t = table("Code", "Name", "Value", "Unit")
    for r, (e, f) in zip(readings, targets, strict=True):
        if f is None:
            t.add_row(e.code, e.name, r.text, unit_text(d.profile, e))
        else:
            t.add_row(f"{e.code}.{f}", e.name, format_field(e, r.raw, f), "")
    out.print(t)
    if (note := footnote(d.profile, [e for e, f in targets if f is None])) is not None:
        out.print(note, markup=False)


def _reading_json(profile: Profile, r: Reading) -> dict[str, object]:
    """A value read, with why the manual leaves its scale or meaning open (value_unverified, null when it does not)."""
    return {**r.as_json(), "value_unverified": json_mark(profile, r.entry)}


def _field_json(r: Reading, field: str) -> dict[str, object]:
    e = r.entry
    value = get_field(e, r.raw, field)
    data: dict[str, object] = {
        "code": f"{e.code}.{field}",
        "name": e.name,
        "field": field,
        "value": value,
        "entry_text": format_value(e, r.raw),
        "raw": r.raw,
    }
    if (meaning := e.field_enums.get(field.upper(), {}).get(value)) is not None:
        data["meaning"] = meaning
    return data


@app.command("set")
def set_(
    ctx: typer.Context,
    assignments: list[str] = typer.Argument(
        ...,
        autocompletion=complete.assignments,
        help="CODE=VALUE in engineering units (e.g. Pn100=40.0); "
        "two-/four-parameter values as the manual shows them (Po001='d 1 21', "
        "Po175=b1200) or one field at a time (Po001.Y=1).",
    ),
    raw: bool = typer.Option(False, "--raw", help="Values are raw register integers, not engineering units."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate and show what would change; write nothing."),
    save: bool = typer.Option(
        None,
        "--save/--no-save",
        help="Store in EEPROM (or keep out of it) as the drive allows; default: the drive's current setting.",
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Validate every value against the profile, write the ones that differ, read back to verify."""
    persisted, stored = None, []
    with drive(ctx) as d:
        from servotool.ops import eeprom, params  # only for writes: `param get` starts without them

        eeprom.check_save_request(d.profile, save)
        results = []
        if dry_run:
            plan = params.prepare_set(d, assignments, raw=raw)
        else:
            plan, outcome = params.set_assignments(d, assignments, raw=raw, save=save)
            results, stored = outcome.results, outcome.stored
            persisted = outcome.persisted if plan.changes or save else None
    if as_json:
        emit_json(
            {
                "dry_run": dry_run,
                "changed": [
                    {
                        "code": e.code,
                        "old": json_value(e, old),
                        "new": json_value(e, new),
                        **texts(e, old=old, new=new),
                        "unit": e.unit,
                        "effect": e.effect,
                        "value_unverified": json_mark(d.profile, e),
                    }
                    for e, old, new in plan.changes
                ],
                "unchanged": [
                    {
                        "code": e.code,
                        "value": json_value(e, v),
                        **({"text": t} if (t := json_text(e, v)) is not None else {}),
                        "unit": e.unit,
                        "value_unverified": json_mark(d.profile, e),
                    }
                    for e, v in plan.unchanged
                ],
                "persisted": persisted,
                "stored": [e.code for e in stored],
            }
        )
        return
    for e, v in plan.unchanged:
        info(f"{e.code} already {spoken(d.profile, e, format_value(e, v))}")
    if dry_run:
        for e, old, new in plan.changes:
            new_text = spoken(d.profile, e, format_value(e, new))
            out.print(f"would set {e.code} ({e.name}): {format_value(e, old)} -> {new_text}", markup=False)
        return
    if persisted is False:
        warn(eeprom.ram_only_warning(d.profile))
    for r in results:
        note = f" [{r.note}]" if r.note and r.entry.effect != "unknown" else ""
        out.print(
            f"{r.entry.code} ({r.entry.name}): {format_value(r.entry, r.old) if r.old is not None else '?'} -> "
            f"{spoken(d.profile, r.entry, format_value(r.entry, r.new))}{note}",
            markup=False,
        )
    if save:  # after the changes it stored
        out.print(f"{count(len(stored), 'value')} stored in EEPROM", markup=False)


def _class(text: str) -> str:
    """An entry class in any case ('un' -> 'Un')."""
    found = class_name(text, LISTABLE)
    if found is None:
        raise UnknownName("class", text, None, suggest(text, LISTABLE), LISTABLE)
    return found


LISTABLE = ("Pn", "Un", "Sn")


@app.command("list")
def list_(
    ctx: typer.Context,
    group: str = typer.Option(
        None,
        "--group",
        "-g",
        autocompletion=complete.groups,
        help="Only this group: the profile's own (see 'profiles "
        "show') or gain, speed, position, torque, io, comm, monitor on every profile.",
    ),
    changed: bool = typer.Option(False, "--changed", help="Only entries that differ from the factory default."),
    cls: str = typer.Option(
        None, "--class", help="Entry class to list: Pn, Un or Sn (default: Pn; with --group, every class in the group)."
    ),
    as_csv: bool = typer.Option(False, "--csv", help="CSV on stdout, for a spreadsheet."),
    as_json: bool = JSON_OPT,
) -> None:
    """Read and show a whole group of entries, with defaults and a changed mark."""
    classes = ("Pn",) if cls is None and group is None else ("Pn", "Un", "Sn") if cls is None else (_class(cls),)
    from servotool.ops import params

    with drive(ctx) as d:
        entries = params.select(d.profile, group=group, classes=classes)
        with progress("reading", len(entries), enabled=not (as_json or as_csv)) as advance:
            readings = d.read_entries(entries, partial=True, progress=advance)
    read = len(readings)
    if changed:
        readings = [r for r in readings if r.changed]
    if as_csv:
        _csv(readings)
        return
    if as_json:
        emit_json(
            [_reading_json(d.profile, r) for r in readings]
            + [
                {"code": e.code, "name": e.name, "value": None, "missing": "not on this drive"}
                for e in d.missing.values()
            ]
        )
        return
    if not readings:  # a line, not a table with no rows
        what = "differs from its factory default" if changed else "could be read"
        out.print(f"{d.profile.model} unit {d.unit}: no entry {what} ({count(read, 'entry')} read)", markup=False)
        return
    t = table("Code", "Name", "Value", "Unit", "Default", "", title=f"{d.profile.model} unit {d.unit}")
    for r in readings:
        e = r.entry
        default = format_value(e, e.default) if e.default is not None else ""
        t.add_row(e.code, e.name, r.text, unit_text(d.profile, e), default, "*" if r.changed else "")
    out.print(t)
    if (note := footnote(d.profile, [r.entry for r in readings])) is not None:
        out.print(note, markup=False)


@app.command("find")
def find(
    ctx: typer.Context,
    words: list[str] = typer.Argument(
        ..., help="Words to look for in codes, names, descriptions and groups (every word must match; any case)."
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Search the profile's entries of every class; no drive needed (the profile from --profile or the port)."""
    profile = resolve(state(ctx).options, need_port=False).profile
    hits = search(profile.entries, words)
    if as_json:
        emit_json(
            [
                {
                    "code": e.code,
                    "class": e.cls,
                    "name": e.name,
                    "unit": e.unit,
                    "group": e.group,
                    "description": e.description,
                }
                for e in hits
            ]
        )
        return
    if not hits:
        out.print(f"nothing in profile {profile.id} matches {' '.join(words)}", markup=False)
        return
    t = table(
        "Code",
        "Class",
        "Name",
        "Unit",
        "Group",
        title=f"{count(len(hits), 'match', 'matches')} in {profile.model} profile '{profile.id}'",
    )
    for e in hits:
        t.add_row(e.code, e.cls, e.name, e.unit, e.group)
    out.print(t)


def _csv(readings: list[Reading]) -> None:
    """The table as CSV on stdout, for a spreadsheet."""
    import csv  # only for --csv

    from servotool.ops.backup_csv import value_text

    w = csv.writer(sys.stdout, lineterminator="\n")
    w.writerow(["code", "name", "value", "unit", "meaning", "default", "changed", "raw"])
    for r in readings:
        e = r.entry
        w.writerow(
            [
                e.code,
                e.name,
                value_text(e, r.raw),
                e.unit,
                e.enum.get(r.raw, ""),
                "" if e.default is None else value_text(e, e.default),
                "yes" if r.changed else "",
                r.raw,
            ]
        )
