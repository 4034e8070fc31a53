"""`servotool param ...`: read, set and list parameters."""

from __future__ import annotations

import typer

from servotool.cli.common import JSON_OPT, drive
from servotool.cli.render import emit_json, info, out, table, warn
from servotool.drive import Reading
from servotool.model.codec import format_field, format_value, get_field, split_field
from servotool.ops import eeprom, params

app = typer.Typer(help="Read, set and list drive parameters.")


@app.command("get")
def get(
    ctx: typer.Context,
    codes: list[str] = typer.Argument(..., help="Vendor codes (e.g. Pn004, Po109, H09-06), role names, or "
                                      "CODE.FIELD for one field of a two-/four-parameter value (e.g. Po001.Y)."),
    as_json: bool = JSON_OPT,
) -> None:
    """Read entries (any class) from the drive."""
    with drive(ctx) as d:
        targets = [split_field(d.profile, c) for c in codes]
        readings = d.read_entries([e for e, _ in targets])
    if as_json:
        emit_json([r.as_json() if f is None else _field_json(r, f) for r, (_, f) in zip(readings, targets,
                                                                                          strict=True)])
        return
    t = table("Code", "Name", "Value", "Unit")
    for r, (e, f) in zip(readings, targets, strict=True):
        if f is None:
            t.add_row(e.code, e.name, r.text, e.unit)
        else:
            t.add_row(f"{e.code}.{f}", e.name, format_field(e, r.raw, f), "")
    out.print(t)


def _field_json(r: Reading, field: str) -> dict[str, object]:
    e = r.entry
    value = get_field(e, r.raw, field)
    data: dict[str, object] = {"code": f"{e.code}.{field}", "name": e.name, "field": field, "value": value,
                               "entry_value": format_value(e, r.raw), "raw": r.raw}
    if (meaning := e.field_enums.get(field.upper(), {}).get(value)) is not None:
        data["meaning"] = meaning
    return data


@app.command("set")
def set_(
    ctx: typer.Context,
    assignments: list[str] = typer.Argument(..., help="CODE=VALUE in engineering units (e.g. Pn100=40.0); "
                                            "two-/four-parameter values as the manual shows them (Po001='d 1 21', "
                                            "Po175=b1200) or one field at a time (Po001.Y=1)."),
    raw: bool = typer.Option(False, "--raw", help="Values are raw register integers, not engineering units."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Validate and show what would change; write nothing."),
    save: bool = typer.Option(None, "--save/--no-save", help="Store in EEPROM (or keep out of it) as the drive "
                              "allows; default: the drive's current setting."),
    as_json: bool = JSON_OPT,
) -> None:
    """Validate every value against the profile, write the ones that differ, read back to verify."""
    persisted, stored = None, []
    with drive(ctx) as d:
        eeprom.check_save_request(d.profile, save)
        plan = params.prepare_set(d, assignments, raw=raw)
        results = []
        if not dry_run:
            outcome = params.set_values(d, plan, save)
            results, stored = outcome.results, outcome.stored
            persisted = outcome.persisted if plan.changes or save else None
    if as_json:
        emit_json({
            "dry_run": dry_run,
            "changed": [{"code": e.code, "old": format_value(e, old), "new": format_value(e, new), "unit": e.unit,
                         "effect": e.effect} for e, old, new in plan.changes],
            "unchanged": [{"code": e.code, "value": format_value(e, v)} for e, v in plan.unchanged],
            "persisted": persisted,
            "stored": [e.code for e in stored],
        })
        return
    for e, v in plan.unchanged:
        info(f"{e.code} already {format_value(e, v)} {e.unit}".rstrip())
    if dry_run:
        for e, old, new in plan.changes:
            out.print(f"would set {e.code} ({e.name}): {format_value(e, old)} -> {format_value(e, new)} {e.unit}",
                      markup=False)
        return
    if persisted is False:
        warn(eeprom.ram_only_warning(d.profile))
    if save:
        out.print(f"{len(stored)} value{'s' if len(stored) != 1 else ''} stored in EEPROM", markup=False)
    for r in results:
        note = f"  [{r.note}]" if r.note and r.entry.effect != "unknown" else ""
        out.print(f"{r.entry.code} ({r.entry.name}): {format_value(r.entry, r.old) if r.old is not None else '?'} -> "
                  f"{format_value(r.entry, r.new)} {r.entry.unit}{note}".replace("  [", " [").rstrip(), markup=False)


@app.command("list")
def list_(
    ctx: typer.Context,
    group: str = typer.Option(None, "--group", "-g", help="Only this group (see 'profiles show')."),
    changed: bool = typer.Option(False, "--changed", help="Only entries that differ from the factory default."),
    cls: str = typer.Option("Pn", "--class", help="Entry class to list: Pn, Un or Sn."),
    as_json: bool = JSON_OPT,
) -> None:
    """Read and show a whole group of entries, with defaults and a changed mark."""
    if cls not in ("Pn", "Un", "Sn"):
        raise typer.BadParameter("use Pn, Un or Sn", param_hint="--class")
    with drive(ctx) as d:
        readings = d.read_entries(params.select(d.profile, group=group, classes=(cls,)))
    if changed:
        readings = [r for r in readings if r.changed]
    if as_json:
        emit_json([r.as_json() for r in readings])
        return
    t = table("Code", "Name", "Value", "Unit", "Default", "", title=f"{d.profile.model} unit {d.unit}")
    for r in readings:
        e = r.entry
        default = format_value(e, e.default) if e.default is not None else ""
        t.add_row(e.code, e.name, r.text, e.unit, default, "*" if r.changed else "")
    out.print(t)
