"""`servotool profiles ...`: list, show and check drive profiles."""

from __future__ import annotations

from pathlib import Path

import typer

from servotool.cli import complete
from servotool.cli.common import JSON_OPT
from servotool.cli.render import emit_json, out, table
from servotool.errors import UnknownName
from servotool.model.codec import field_range, format_value
from servotool.model.loader import builtin_dir, builtin_ids, load_profile, read_profile
from servotool.model.lookup import COMMON_GROUPS, group_members, suggest
from servotool.model.profile import Entry, IdentityCheck, Profile
from servotool.model.roles import sim_extensions
from servotool.words import count

app = typer.Typer(no_args_is_help=True, help="List, show and check drive profiles.")


@app.command("list")
def list_(as_json: bool = JSON_OPT) -> None:
    """The built-in profiles."""
    rows = []
    for pid in builtin_ids():
        p = load_profile(pid)
        rows.append(
            {
                "id": p.id,
                "model": p.model,
                "vendor": p.vendor,
                "version": p.version,
                "entries": len(p.entries),
                "unverified": sum(1 for e in p.entries if e.unverified),
                "description": p.description,
            }
        )
    if as_json:
        emit_json(rows)
        return
    t = table(
        "Id", "Model", "Vendor", "Version", "Entries", "Unverified", "Description", title=f"Profiles in {builtin_dir()}"
    )
    for r in rows:
        t.add_row(*(str(r[k]) for k in ("id", "model", "vendor", "version", "entries", "unverified", "description")))
    out.print(t)


@app.command("show")
def show(
    profile: str = typer.Argument(..., autocompletion=complete.profiles, help="Profile id or YAML file."),
    unverified: bool = typer.Option(False, "--unverified", help="Only entries the manual leaves open, with why."),
    group: str = typer.Option(
        None,
        "--group",
        "-g",
        help="Only this group (its id, or a common name: gain, speed, position, torque, io, comm, monitor).",
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """A profile's settings, roles and entries."""
    p = load_profile(profile)
    members = p.entries if group is None else group_members(p.entries, group)
    if members is None:
        known = sorted({e.group for e in p.entries if e.group} | set(COMMON_GROUPS))
        raise UnknownName("group", str(group), p.id, suggest(str(group), known), known)
    entries = [e for e in members if not unverified or e.unverified]
    if as_json:
        emit_json(
            {
                "id": p.id,
                "model": p.model,
                "vendor": p.vendor,
                "version": p.version,
                "source": p.source,
                "address_rule": p.address_rule,
                "unverified_note": p.unverified_note,
                "serial": {**vars(p.line), "unit": p.default_unit, "boost": _boost_json(p)},
                "limits": vars(p.limits),
                "word_order": p.word_order,
                "persistence": vars(p.persistence),
                "roles": p.roles,
                "entries": [_entry_json(e) for e in entries],
                "dead_man": vars(p.dead_man) if p.dead_man is not None else None,
                "identity": _identity_json(p),
                "sim_extensions": [{"what": x.what, "why": x.why} for x in sim_extensions(p)],
            }
        )
        return
    out.print(f"[bold]{p.model}[/bold] ({p.vendor}) profile '{p.id}' v{p.version}: {p.description}")
    out.print(f"source: {p.source}", markup=False)
    out.print(f"addresses: {p.address_rule}", markup=False)
    lim = p.limits
    out.print(
        f"serial: {p.line.describe()}, unit {p.default_unit}; max {lim.max_read} regs/read, "
        f"{lim.max_write}/write; 32-bit word order {p.word_order}; EEPROM: {p.persistence.mode}",
        markup=False,
    )
    out.print(f"line boost: {_boost_text(p)}", markup=False)
    if p.unverified_note:
        out.print(f"[yellow]note:[/yellow] {p.unverified_note}")
    if unverified:
        if entries:
            t = table(
                "Code", "Name", "Why unverified", title=count(len(entries), "unverified entry", "unverified entries")
            )
            for e in entries:
                t.add_row(e.code, e.name, e.unverified)
            out.print(t)
        else:
            out.print("no unverified entry", markup=False)
        _print_dead_man(p)
        _print_identity(p, only_unverified=True)
        found = sim_extensions(p)
        if found:
            out.print("simulator extensions (not in the manual):", markup=False)
            for x in found:
                out.print(f"  {x.what}: {x.why}", markup=False)
        return
    t = table("Code", "Class", "Name", "Address", "Type", "Min", "Max", "Default", "Unit", "Effect", "")
    for e in entries:
        t.add_row(
            e.code,
            e.cls,
            e.name,
            f"{e.address} (0x{e.address:04X})",
            e.type,
            format_value(e, e.min),
            format_value(e, e.max),
            format_value(e, e.default) if e.default is not None else "",
            e.unit,
            e.effect if e.cls == "Pn" else e.access,
            "?" if e.unverified else "",
        )
    out.print(t)
    out.print("roles: " + ", ".join(f"{k}={v}" for k, v in sorted(p.roles.items())), markup=False)
    _print_identity(p)


def _identity_json(p: Profile) -> dict[str, object] | None:
    """The identity section: the firmware and model entries, and every check read before the first write."""
    ident = p.identity
    if ident is None:
        return None
    return {
        "firmware": ident.firmware or None,
        "model": ident.model or None,
        "checks": [
            {
                "code": c.code or None,
                "address": c.address,
                "words": c.words,
                "absent": c.absent,
                "range": list(c.range) if c.range else None,
                "sim": c.sim,
                "source": c.source,
                "unverified": c.unverified or None,
            }
            for c in ident.checks
        ],
    }


def _answers(c: IdentityCheck) -> str:
    """What a drive of this family answers for one check."""
    if c.absent:
        return "exception 02 (no register)"
    text = f"{c.range[0]}..{c.range[1]}" if c.range else "present (any value)"
    return text + (f" (sim {c.sim})" if c.sim is not None else "")


def _print_identity(p: Profile, *, only_unverified: bool = False) -> None:
    """The identity checks as a table that wraps its notes (readable at 80 columns)."""
    ident = p.identity
    if ident is None:
        if not only_unverified:
            out.print("identity: none (a drive is not checked before writing)", markup=False)
        return
    checks = [c for c in ident.checks if c.unverified or not only_unverified]
    if not checks:
        return
    named = ", ".join(f"{k} {v}" for k, v in (("firmware", ident.firmware), ("model", ident.model)) if v)
    t = table(
        "Check",
        "Address",
        "Answers",
        "Note",
        drop=("Address",),
        title=f"identity, checked before the first write{f' ({named})' if named else ''}",
    )
    for c in checks:
        note = c.source + (f"; unverified: {c.unverified}" if c.unverified else "")
        t.add_row(c.code or "-", f"{c.address} (0x{c.address:04X})", _answers(c), note)
    out.print(t)


def _entry_json(e: Entry) -> dict[str, object]:
    """Everything a third party needs to build the entry's registers: address, words and their order, how they
    combine, and the layout of a multi-field value."""
    out: dict[str, object] = {
        "code": e.code,
        "class": e.cls,
        "name": e.name,
        "address": e.address,
        "words": e.words,
        "type": e.type,
        "word_order": e.word_order,
        "combine": e.combine,
        "unit": e.unit,
        "scale": e.scale,
        "min": e.min,
        "max": e.max,
        "default": e.default,
        "access": e.access,
        "effect": e.effect,
        "group": e.group,
        "format": e.format,
        "copy": e.copy,
        "source": e.source,
        "unverified": e.unverified,
    }
    if e.combine == "decimal":
        out["digits"] = e.digits  # decimal digits each word carries
    if e.fields:
        # field i holds bits [width*i, width*(i+1)) of the raw value (i = 0 lowest)
        out["fields"] = [
            {
                "name": f,
                "bit_offset": e.field_width * i,
                "width": e.field_width,
                "range": list(field_range(e, f)),
                "enum": {str(k): v for k, v in e.field_enums.get(f.upper(), {}).items()},
            }
            for i, f in enumerate(e.fields)
        ]
    if e.bits:
        out["bits"] = {str(k): v for k, v in e.bits.items()}
    if e.enum:
        out["enum"] = {str(k): v for k, v in e.enum.items()}
    if e.cls == "Fn":
        out["trigger"] = e.trigger
    return out


@app.command("check")
def check(
    files: list[str] = typer.Argument(
        None, help="Profile YAML files or built-in profile ids (default: every built-in profile)."
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Validate profiles; print every problem with its location (exit 2 if any)."""
    bad = 0
    report = []
    for path in _profile_paths(files or builtin_ids()):
        profile, problems = read_profile(path)
        report.append(
            {
                "file": str(path),
                "ok": profile is not None,
                "problems": problems,
                "entries": len(profile.entries) if profile else 0,
            }
        )
        if as_json:
            bad += profile is None
            continue
        for line in problems:
            out.print(line, markup=False)
        if profile is None:
            bad += 1
        else:
            out.print(f"{path}: ok ({len(profile.entries)} entries, {len(profile.roles)} roles)", markup=False)
    if as_json:
        emit_json(report)
    if bad:
        raise typer.Exit(2)


def _profile_paths(names: list[str]) -> list[Path]:
    """A name that is no existing file but a built-in id stands for that built-in profile's file."""
    ids = {i.lower(): i for i in builtin_ids()}
    return [
        builtin_dir() / f"{ids[n.lower()]}.yaml" if not Path(n).exists() and n.lower() in ids else Path(n)
        for n in names
    ]


def _boost_json(p: Profile) -> dict[str, object]:
    b = p.boost
    if not b.available:
        return {"available": False, "why": b.none or None, "source": b.source or None}
    return {
        "available": True,
        "code": b.code,
        "to_baud": b.to_baud,
        "rates": {str(k): v for k, v in b.rates.items()},
        "source": b.source,
        "unverified": b.unverified or None,
    }


def _boost_text(p: Profile) -> str:
    """Whether and how the line is raised for long exchanges (serial.boost), with what is not checked."""
    b = p.boost
    if not b.available:
        return f"none: {b.none}" if b.none else "none (the profile does not say)"
    text = f"{b.code} raised to {b.to_baud} baud for identification, trace, backup and restore ({b.source})"
    return text + (f"; unverified: {b.unverified}" if b.unverified else "")


def _print_dead_man(p: Profile) -> None:
    """What stops host motion when the host dies, as the profile describes it."""
    dm = p.dead_man
    if dm is None:
        out.print("dead-man route: not described by this profile", markup=False)
        return
    out.print(f"dead-man route: {dm.route}: {dm.reason} (source: {dm.source})", markup=False)
    if dm.unverified:
        out.print(f"  unverified: {dm.unverified}", markup=False)
    if dm.if_host_dies:
        out.print(f"  if the host dies: {dm.if_host_dies}", markup=False)
