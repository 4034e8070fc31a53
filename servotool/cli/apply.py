"""`servotool param apply FILE`: bring a drive to a desired set of settings (ops.apply), idempotently."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import typer

from servotool.cli.common import JSON_OPT, drives_for, resolved_from, state
from servotool.cli.render import emit_json, info, out, warn
from servotool.cli.values import footnote, spoken
from servotool.connection import ConnectOptions, merge
from servotool.model.codec import format_value
from servotool.model.loader import load_profile
from servotool.words import count

if TYPE_CHECKING:
    from servotool.model.profile import Profile
    from servotool.ops.apply import ApplyResult

app = typer.Typer(help="Bring a drive to a desired set of settings.")


@app.command("apply")
def apply_cmd(
    ctx: typer.Context,
    file: Path = typer.Argument(
        ..., help="Settings file (profile, unit, save, parameters: CODE: VALUE in engineering units), or a backup."
    ),
    check: bool = typer.Option(False, "--check", help="Write nothing: say what would change (exit 1 if anything)."),
    diff: bool = typer.Option(False, "--diff", help="Show each change as before/after lines."),
    as_json: bool = JSON_OPT,
) -> None:
    """Write only the parameters that differ from FILE, verified, and say changed or unchanged.

    Exit status 0 when the drive is as FILE says (unchanged, or changed and read back); with --check, 0 when
    nothing would change and 1 when something would; 2 for a bad file, 1 when the drive or link fails (what was
    written is rolled back), 3 when a value does not read back.
    """
    from servotool.ops import apply, desired

    named = desired.profile_named(file)  # the file's profile and unit fill in what the command line leaves open
    loaded = desired.load(file, load_profile(named) if named else None)
    opts = merge(state(ctx).options, ConnectOptions(profile=loaded.profile, unit=loaded.unit))
    res = resolved_from(opts)
    if loaded.from_backup and res.profile.id != loaded.profile:
        loaded = desired.load(file, res.profile)  # a backup of another profile: refused by its loader
    desired.check(loaded, res.profile)  # before the port opens
    with drives_for(ctx, res, [res.unit]) as (d,):
        result = apply.apply(d, loaded, check=check)
    if as_json:
        emit_json({"file": str(file), "unit": d.unit, "profile": d.profile.id, **result.as_json()})
    else:
        _show(d.profile, result, diff)
    if check and result.changes:
        raise typer.Exit(1)


def _show(profile: Profile, result: ApplyResult, diff: bool) -> None:
    """The changes (or with diff, before/after lines), then one line: changed, unchanged or would change."""
    from servotool.ops.apply import WOULD_CHANGE
    from servotool.ops.eeprom import ram_only_warning

    if result.compared == "RAM":
        info(
            "compared with the drive's RAM: what EEPROM holds cannot be read over Modbus; a value RAM holds already "
            "is left as it is ('param restore' writes every value of a backup again under the EEPROM setting)"
        )
    if result.skipped:
        codes = [code for code, _why in result.skipped]
        shown = ", ".join(codes[:4]) + (" ..." if len(codes) > 4 else "")
        info(f"left out {count(len(codes), 'entry')} of the backup as 'param restore' does ({shown}): --json says why")
    for code in result.missing:
        warn(f"{code}: not on this drive; left out")
    verb = "would set" if result.status == WOULD_CHANGE else "set"
    if diff and result.changes:
        before, after = result.diff_text()
        out.print("--- drive\n+++ desired", markup=False)
        for old, new in zip(before.splitlines(), after.splitlines(), strict=True):
            out.print(f"-{old}\n+{new}", markup=False)
    elif result.changes:
        for s in result.changes:
            e = s.entry
            out.print(
                f"{verb} {e.code} ({e.name}): {format_value(e, s.before)} -> "
                f"{spoken(profile, e, format_value(e, s.desired))}",
                markup=False,
            )
    same = len(result.settings) - len(result.changes)
    if result.status == WOULD_CHANGE:
        out.print(f"would change {count(len(result.changes), 'parameter')}; {same} already as desired", markup=False)
    elif result.changes:
        out.print(
            f"changed: {count(len(result.changes), 'parameter')} written and read back; {same} already as desired",
            markup=False,
        )
        if result.persisted is False:
            warn(ram_only_warning(profile))
        if result.needs_power_cycle:
            out.print("power-cycle the drive for: " + ", ".join(result.needs_power_cycle), markup=False)
    else:
        out.print(f"unchanged: {count(len(result.settings), 'parameter')} already as desired", markup=False)
    if (note := footnote(profile, [s.entry for s in result.changes])) is not None:
        out.print(note, markup=False)
