"""`servotool raw read|write`: registers by address, outside the profile."""

from __future__ import annotations

import typer

from servotool.cli.common import JSON_OPT, confirm, drive, resolved
from servotool.cli.render import emit_json, out, table
from servotool.errors import ServoError, UsageError
from servotool.ops import raw

app = typer.Typer(no_args_is_help=True, help="Read and write registers by address (outside the profile).")


@app.command("read")
def read(
    ctx: typer.Context,
    address: str = typer.Argument(..., help="First register address: decimal or hex (0x2004)."),
    count: int = typer.Argument(1, help="Number of registers (FC03)."),
    as_json: bool = JSON_OPT,
) -> None:
    """Read holding registers and show them in decimal, signed and hex, with the entry each belongs to."""
    start = raw.parse_address(address)
    with drive(ctx) as d:
        words = raw.read_registers(d, start, count)
        owners = [raw.owner(d, start + i) for i in range(len(words))]
    if as_json:
        emit_json(
            [
                {
                    "address": start + i,
                    "value": w,
                    "signed": w - 0x10000 if w >= 0x8000 else w,
                    "entry": e.code if e else None,
                }
                for i, (w, e) in enumerate(zip(words, owners, strict=True))
            ]
        )
        return
    t = table("Address", "Hex", "Value", "Signed", "Hex value", "Entry")
    for i, (w, e) in enumerate(zip(words, owners, strict=True)):
        t.add_row(
            str(start + i),
            f"0x{start + i:04X}",
            str(w),
            str(w - 0x10000 if w >= 0x8000 else w),
            f"0x{w:04X}",
            f"{e.code} {e.name}" if e else "",
        )
    out.print(t)


@app.command("write")
def write(
    ctx: typer.Context,
    assignment: str = typer.Argument(..., help="ADDR=VALUE: decimal or hex, e.g. 0x2004=300 or 8196=0x012C."),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask (real drives only; the simulator never asks)."),
    as_json: bool = JSON_OPT,
) -> None:
    """Write one register (FC06) and read it back. No profile check: the drive is the only judge."""
    if "=" not in assignment:
        raise UsageError(f"'{assignment}' is not ADDR=VALUE")
    left, _, right = assignment.partition("=")
    address, value = raw.parse_address(left), raw.parse_word(right)
    simulated = resolved(ctx).simulated
    with drive(ctx) as d:
        entry = raw.owner(d, address)
        what = f"register {address} (0x{address:04X}" + (f", {entry.code} {entry.name}" if entry else "") + ")"
        if not simulated and not confirm(f"Write {value} to {what} of unit {d.unit}?", yes):
            raise ServoError("cancelled: nothing was written")
        back = raw.write_register(d, address, value)
    if as_json:
        emit_json({"address": address, "value": back, "entry": entry.code if entry else None, "verified": True})
    else:
        out.print(f"{what}: {back} (0x{back:04X}), verified by read-back", markup=False)
