"""`servotool stop`: zero speed, servo off and forced inputs released on a drive, whatever moved it; then read back."""

from __future__ import annotations

import typer

from servotool.cli.common import JSON_OPT, drives, resolved
from servotool.cli.render import emit_json, notice
from servotool.errors import DeviceError
from servotool.motion.stop import stop_drive
from servotool.ops.scan import parse_units

STOP_UNCONFIRMED = 4


def stop(
    ctx: typer.Context,
    units: str = typer.Option(
        None, "--units", help="Unit ids to stop, e.g. 1-4 or 1,3 (default: the connection's unit, -u)."
    ),
    wait: float = typer.Option(5.0, "--wait", help="Longest wait for the motor to come to rest, in seconds."),
    as_json: bool = JSON_OPT,
) -> None:
    """Stop the motor: zero speed, servo off and forced inputs released (SD25 So-58), then read back.

    Works on every profile, whatever moved the motor (a JOG, a dead servotool process, another master): nothing is
    checked or read before the first write (no identity check, no journal, no lock). Exit 4 when the drive could not
    be read back at rest with its servo off.
    """
    if not (0 <= wait <= 60):
        raise typer.BadParameter("must be 0..60 s", param_hint="--wait")
    ids = parse_units(units) if units else [resolved(ctx).unit]
    results = []
    with drives(ctx, ids, bare=True) as found:  # in the shell, on the port it keeps open
        for d in found:
            try:
                report = stop_drive(d, wait)
            except DeviceError as exc:  # not even the first write went out
                results.append((d.unit, None, str(exc)))
                continue
            results.append((d.unit, report, ""))
    unconfirmed = [u for u, r, _ in results if r is None or not r.confirmed]
    if as_json:
        emit_json(
            [
                {"unit": u, **(r.as_json() if r is not None else {"confirmed": False, "problems": [why]})}
                for u, r, why in results
            ]
        )
    else:
        for u, r, why in results:
            text = r.describe() if r is not None else f"COULD NOT CONFIRM THE MOTOR STOPPED: {why}"
            notice(f"unit {u}: {text}")
    if unconfirmed:
        raise typer.Exit(STOP_UNCONFIRMED)
