"""`servotool param backup|diff|restore|reset`: parameter sets as files, and the way back to them."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from servotool.cli.common import JSON_OPT, boosted, confirm, drive, resolved, state
from servotool.cli.render import emit_json, err, info, out, progress, table, warn
from servotool.cli.values import footnote, json_mark, texts, unit_text
from servotool.errors import ServoError, UsageError
from servotool.model.codec import format_value, json_value
from servotool.model.loader import load_profile
from servotool.model.profile import Profile
from servotool.words import agree, count

if TYPE_CHECKING:  # imported by the commands that use them: `param get` and `set` share this group
    from servotool.drive import Drive
    from servotool.ops import backup, restore

app = typer.Typer(help="Back up, compare and restore drive parameters; factory reset.")

MARK = {"power_cycle": "power cycle", "servo_off": "servo off"}


def _where(text: str) -> None:
    """Where the automatic backup went: shown even with --quiet, since it is the way back."""
    err.print(text, markup=False)


@app.command("backup")
def backup_cmd(
    ctx: typer.Context,
    output: Path = typer.Option(
        None, "--output", "-o", help="Backup file (default: MODEL-unitN-DATE.yaml here, or .csv)."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing file."),
    fmt: str = typer.Option(
        None,
        "--format",
        help="yaml (checksummed; the default) or csv (for a spreadsheet; "
        "restore reads it too). Default: from the file name's suffix.",
    ),
    snapshot: bool = typer.Option(
        False,
        "--snapshot",
        help="A snapshot for version control: no time stamp or checksum, one line per value with its reading as a "
        "comment, so a diff of two shows only what changed (default name PROFILE-unitN.yaml).",
    ),
    machine: str = typer.Option(
        None, "--machine", help="The machine a snapshot names in its header. Env: SERVOTOOL_MACHINE."
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Save every readable parameter (and the drive's identity) to a checksummed YAML file, or a CSV."""
    import os

    from servotool.ops import backup
    from servotool.ops.params import select

    kind = (fmt or (output.suffix.lstrip(".") if output is not None and output.suffix else "yaml")).lower()
    if kind not in ("yaml", "yml", "csv"):
        raise UsageError(f"--format must be yaml or csv, not '{fmt or kind}'")
    if snapshot and kind == "csv":
        raise UsageError("a snapshot is YAML: give --snapshot or --format csv, not both")
    machine = machine or os.environ.get("SERVOTOOL_MACHINE") or ""
    if machine and not snapshot:
        raise UsageError("--machine names the machine in a snapshot's header: give --snapshot too")
    backup.check_output(output or Path(f"new.{kind}"), force=force)  # before reading the drive (24 s at 1200 Bd)
    with drive(ctx) as d:
        entries = select(d.profile)
        with (
            boosted(ctx, [d], "the backup"),
            progress("reading parameters", len(entries), enabled=not as_json) as advance,
        ):
            b = backup.take(d, progress=advance)
        suffix = "csv" if kind == "csv" else "yaml"
        if snapshot:
            b.machine = machine
            path = output or Path(f"{d.profile.id}-unit{d.unit}.yaml")
            backup.check_output(path, force=force)
        else:
            path = output or Path(f"{d.profile.id}-unit{d.unit}-{b.created[:19].replace(':', '')}.{suffix}")
        backup.save(b, d.profile, path, force=force, fmt="snapshot" if snapshot else suffix)
    if as_json:
        emit_json(
            {
                "file": str(path),
                "format": "snapshot" if snapshot else "csv" if kind == "csv" else "yaml",
                "entries": len(b.values),
                "checksum": b.checksum(),
                "identity": b.identity,
                "missing": b.missing,
            }
        )
    else:
        lacking = f" ({len(b.missing)} not on this drive, marked in the file)" if b.missing else ""
        out.print(f"{count(len(b.values), 'parameter')} saved to {path}{lacking}", markup=False)


@app.command("diff")
def diff_cmd(
    ctx: typer.Context,
    file: Path = typer.Argument(
        None,
        help="Backup file (compared with the drive, or with FILE2); none with --factory: "
        "the drive against its factory defaults.",
    ),
    file2: Path = typer.Argument(None, help="Second backup file: compare the two files, no drive needed."),
    from_default: bool = typer.Option(
        False, "--factory", "--changed-from-default", help="Compare with the factory defaults (the drive's, or FILE's)."
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Differences between the drive and a file, two files, a file or the drive and the factory defaults.

    A diff writes nothing, so an edited file or one of another model is compared anyway, with a warning. Exit
    status 0 when they are equal, 1 when they differ (for scripts and CI).
    """
    from servotool.ops import backup
    from servotool.ops.eeprom import compared_memory

    opts = state(ctx).options
    if file2 is not None and from_default:
        raise UsageError("give FILE2 or --factory, not both")
    if file is None and not from_default:
        raise UsageError("give a backup FILE to compare with, or --factory for the factory defaults")
    if file is None:
        with drive(ctx) as d:
            profile = d.profile
            current = _read_all(d, as_json)
            missing = list(d.missing)
        _differ(
            _show_diff(
                profile,
                backup.diff(profile, current, backup.defaults(profile)),
                ("drive", "factory default"),
                missing,
                as_json,
                compared_memory(profile),
            )
        )
        return

    def load(path: Path, profile: Profile) -> backup.Backup:
        b = backup.load(path, profile, force=True)
        for w in b.warnings:
            warn(w)
        return b

    missing: list[str] = []  # entries the drive lacks (a drive diff only)
    compared: str | None = None  # the drive's memory a drive diff compared
    if file2 is not None or from_default:
        name = opts.profile or backup.profile_of(file)
        if name is None:
            raise UsageError(f"{file}: cannot tell its profile; give --profile")
        profile = load_profile(name)
        a = load(file, profile)
        b_values = backup.defaults(profile) if from_default else load(file2, profile).values
        labels = (str(file), "factory default" if from_default else str(file2))
        diffs = backup.diff(profile, a.values, b_values)
    else:
        with drive(ctx) as d:
            profile = d.profile
            a = load(file, profile)
            current = _read_all(d, as_json)
            missing = list(d.missing)
        labels = ("drive", str(file))
        diffs = [x for x in backup.diff(profile, current, a.values) if x.entry.code not in missing]
        compared = compared_memory(profile)
    _differ(_show_diff(profile, diffs, labels, missing, as_json, compared))


def _differ(differences: int) -> None:
    """Exit 1 when a comparison found differences (0 when equal), as diff(1) does."""
    if differences:
        raise typer.Exit(1)


def _read_all(d: Drive, as_json: bool) -> dict[str, int]:
    """Every readable parameter of the drive (code -> raw), with a progress bar on a terminal."""
    from servotool.ops.params import read_settings, select

    with progress("reading the drive", len(select(d.profile)), enabled=not as_json) as advance:
        return read_settings(d, advance)


def _show_diff(
    profile: Profile,
    diffs: list[backup.Difference],
    labels: tuple[str, str],
    missing: list[str],
    as_json: bool,
    compared: str | None = None,
) -> int:
    """The differences (returns how many); compared names the drive's memory a drive diff read (RAM, which may not
    be EEPROM)."""
    if as_json:
        differences = [{**x.as_json(), "value_unverified": json_mark(profile, x.entry)} for x in diffs]
        data = {"a": labels[0], "b": labels[1], "differences": differences, "missing": missing}
        emit_json({**data, **({"compared": compared} if compared else {})})
        return len(diffs)
    if compared == "RAM":
        info(
            "compared with the drive's RAM: what EEPROM holds (what a power cycle brings back) cannot be read over "
            "Modbus and may differ ('param restore' writes every value under the EEPROM setting)"
        )
    elif compared:
        info(f"compared with the drive's {compared}")
    drive = f"drive {compared.split()[0]}" if compared else ""
    labels = (drive or labels[0], labels[1])
    if not diffs:
        out.print(f"no differences between {labels[0]} and {labels[1]}", markup=False)
        return 0
    t = table("Code", "Name", labels[0], labels[1], "Unit", "Needs")
    for x in diffs:
        e = x.entry
        t.add_row(
            e.code,
            e.name,
            "" if x.a is None else format_value(e, x.a),
            "" if x.b is None else format_value(e, x.b),
            unit_text(profile, e),
            MARK.get(e.effect, ""),
        )
    out.print(t)
    if (note := footnote(profile, [x.entry for x in diffs])) is not None:
        out.print(note, markup=False)
    return len(diffs)


@app.command("restore")
def restore_cmd(
    ctx: typer.Context,
    file: Path = typer.Argument(..., help="Backup file to restore."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Show the plan; write nothing."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation."),
    force: bool = typer.Option(False, "--force", help="Accept a file of another model or with a bad checksum."),
    only: str = typer.Option(None, "--only", help="Restore only this group (a portable subset)."),
    include: list[str] = typer.Option(None, "--include", help="Also restore this axis-specific entry (repeatable)."),
    ram_only: bool = typer.Option(
        False,
        "--ram-only",
        help="Compare with the drive's RAM only and write what differs there; by default a drive whose EEPROM "
        "cannot be read gets every value written again under the EEPROM setting.",
    ),
    as_json: bool = JSON_OPT,
) -> None:
    """Write the differing entries, verified, after an automatic backup; roll back on failure.

    Reads show the drive's RAM: where EEPROM may hold something else (SD25, IS620P), every other backup value is
    written again under the EEPROM setting, as 'param set --save' does, unless --ram-only.
    """
    from servotool.ops import backup, restore
    from servotool.ops.eeprom import compared_memory
    from servotool.ops.params import read_settings, select

    profile = resolved(ctx).profile
    b = backup.load(file, profile, force=force)  # every file problem is refused before connecting
    for w in b.warnings:
        warn(w)
    speed = profile.boost.code if profile.boost.available else None
    names_speed = speed is not None and any(profile.entry(c).code == speed for c in include or [])
    with drive(ctx) as d, boosted(ctx, [d], "the restore", allow=not names_speed):
        entries = select(d.profile)
        with progress("reading the drive", len(entries), enabled=not as_json) as advance:
            current = read_settings(d, progress=advance)
        plan = restore.restore_changes(d.profile, b, current, only=only, include=include or [], ram_only=ram_only)
        compared = compared_memory(d.profile)
        if not as_json:
            _show_plan(d.profile, plan, compared)
        if dry_run or plan.empty:
            if as_json:
                emit_json(
                    {
                        "dry_run": dry_run,
                        "compared": compared,
                        "changes": _changes_json(d.profile, plan),
                        "store_again": [e.code for e, _ in plan.again],
                        "written": [],
                        "stored_again": [],
                        "skipped": [{"code": e.code, "why": why} for e, why in plan.skipped],
                        "missing": [e.code for e in plan.missing],
                        "refused": [],
                    }
                )
            elif plan.empty:
                out.print(_nothing_to_restore(plan, compared), markup=False)
            return
        total = len(plan.changes) + len(plan.again)
        if not confirm(f"Write {count(total, 'parameter')}?", yes):
            raise ServoError("restore cancelled: nothing was written")
        # The automatic backup reads every entry before the first write: at a slow baud rate that is most of it.
        with progress("automatic backup, then writing", len(entries) + total, enabled=not as_json) as advance:
            report = restore.restore(
                d, b, plan, progress=lambda _entry: advance(1), notice=_where, backup_progress=advance
            )
    if as_json:
        emit_json(
            {
                "dry_run": False,
                "compared": compared,
                "changes": _changes_json(d.profile, plan),
                "store_again": [e.code for e, _ in plan.again],
                "written": [e.code for e in report.written],
                "stored_again": [e.code for e in report.stored_again],
                "auto_backup": str(report.auto_backup),
                "persisted": report.persisted,
                "skipped": [{"code": e.code, "why": why} for e, why in plan.skipped],
                "missing": [e.code for e in plan.missing],
                "refused": [{"code": e.code, "why": why} for e, why in report.refused],
            }
        )
        return
    for e, why in report.refused:
        warn(f"{e.code} ({e.name}) not restored: the drive refuses writes there ({why})")
    if report.written or not report.stored_again:
        out.print(f"{count(len(report.written), 'parameter')} restored and verified by read-back", markup=False)
    if report.stored_again:
        out.print(
            f"{count(len(report.stored_again), 'value')} RAM already held written again under the EEPROM setting "
            f"and verified by read-back, to store {agree(len(report.stored_again), 'it', 'them')}",
            markup=False,
        )
    if plan.ram_only and report.persisted:
        warn("--ram-only: values that differ only in EEPROM were not compared, and stay as they are")
    if not report.persisted:
        # restore asks for EEPROM, so this is a drive that cannot store over Modbus
        warn(f"the drive keeps these values in RAM only, lost at power-off: {d.profile.persistence.note}")
    if plan.needs_power_cycle:
        out.print("power-cycle the drive for: " + ", ".join(e.code for e in plan.needs_power_cycle), markup=False)


def _changes_json(profile: Profile, plan: restore.RestoreChanges) -> list[dict[str, object]]:
    return [
        {
            "code": e.code,
            "old": json_value(e, old),
            "new": json_value(e, new),
            **texts(e, old=old, new=new),
            "unit": e.unit,
            "effect": e.effect,
            "value_unverified": json_mark(profile, e),
        }
        for e, old, new in plan.changes
    ]


def _show_plan(profile: Profile, plan: restore.RestoreChanges, compared: str) -> None:
    if plan.changes:
        t = table(
            "Code",
            "Name",
            f"Drive {compared.split()[0]}",
            "Backup",
            "Unit",
            "Needs",
            title=f"{count(len(plan.changes), 'change')}, in order",
        )
        for e, old, new in plan.changes:
            t.add_row(
                e.code,
                e.name,
                format_value(e, old),
                format_value(e, new),
                unit_text(profile, e),
                MARK.get(e.effect, ""),
            )
        out.print(t)
        if (note := footnote(profile, [e for e, _, _ in plan.changes])) is not None:
            out.print(note, markup=False)
    if plan.again:
        info(
            f"and {count(len(plan.again), 'value')} the drive's RAM already holds, written again under the EEPROM "
            "setting: what EEPROM holds cannot be read over Modbus (--ram-only writes only what differs in RAM)"
        )
    if plan.store:
        info("the drive's store function runs at the end: what its EEPROM holds cannot be read over Modbus")
    for e, why in plan.skipped:
        info(f"skipped {e.code}: {why}")


def _nothing_to_restore(plan: restore.RestoreChanges, compared: str) -> str:
    if compared != "RAM":
        return "nothing to restore: the drive already matches"
    why = " (--ram-only: what EEPROM holds was not compared)" if plan.ram_only else ""
    return f"nothing to restore: the drive's RAM already matches{why}"


@app.command("reset")
def reset_cmd(
    ctx: typer.Context,
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask for confirmation."),
    as_json: bool = JSON_OPT,
) -> None:
    """Factory defaults through the drive's own function, after an automatic backup."""
    from servotool.ops import backup, restore
    from servotool.ops.params import select

    with drive(ctx) as d:
        d.profile.need_role("factory_reset", "param reset")
        if not confirm(f"Reset {d.profile.model} unit {d.unit} to factory defaults?", yes):
            raise ServoError("factory reset cancelled: nothing was written")
        count_pn = len(select(d.profile))
        with progress("automatic backup", count_pn, enabled=not as_json) as advance:
            auto = restore.factory_reset(d, notice=_where, progress=advance)
        with progress("checking the defaults", count_pn, enabled=not as_json) as advance:
            left = restore.not_at_default(d, progress=advance)
        before = backup.load(auto, d.profile).values
    cycle = [
        e.code
        for e in d.profile.of_class("Pn")
        if e.effect == "power_cycle" and before.get(e.code, e.default) != e.default
    ]
    if as_json:
        emit_json({"auto_backup": str(auto), "not_at_default": [e.code for e, _ in left], "power_cycle": cycle})
        return
    out.print(f"factory defaults restored; previous settings saved in {auto}", markup=False)
    if left:
        warn("still not at the factory default: " + ", ".join(f"{e.code}={format_value(e, raw)}" for e, raw in left))
    if cycle:
        out.print("power-cycle the drive for the defaults of: " + ", ".join(cycle), markup=False)
