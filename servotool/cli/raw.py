"""`servotool raw read|write`: registers by address, outside the profile."""

from __future__ import annotations

import csv
import sys
from collections.abc import Iterator

import typer

from servotool.cli.common import JSON_OPT, confirm, drive, resolved
from servotool.cli.render import emit_json, emit_json_line, out, table
from servotool.errors import ServoError, UsageError
from servotool.model.profile import Entry
from servotool.ops import raw

app = typer.Typer(no_args_is_help=True, help="Read and write registers by address (outside the profile).")


@app.command("read")
def read(
    ctx: typer.Context,
    address: str = typer.Argument(..., help="First register address: decimal or hex (0x2004)."),
    count: int = typer.Argument(1, help="Number of values (registers for 16-bit types, register pairs for 32-bit)."),
    fc: int = typer.Option(3, "--fc", help="1 coils, 2 discrete inputs, 3 holding registers, 4 input registers."),
    kind: str = typer.Option("uint16", "--type", help="int16, uint16, int32, uint32 or float32."),
    word_order: str = typer.Option("big", "--word-order", help="32-bit values: big (high word first) or little."),
    interval: float | None = typer.Option(None, "--interval", help="Poll every S seconds, one row per poll."),
    polls: int | None = typer.Option(None, "--count", help="With --interval: stop after N polls (default: Ctrl-C)."),
    as_csv: bool = typer.Option(False, "--csv", help="CSV on stdout: one row per value, or per poll."),
    as_json: bool = JSON_OPT,
) -> None:
    """Read holding registers (FC03; --fc 4 input registers, 1 coils, 2 discrete inputs) and show them in decimal,
    signed and hex, with the entry each belongs to; with --type as 16- or 32-bit integers or floats; with
    --interval, polled."""
    start = raw.parse_address(address)
    if as_csv and as_json:
        raise UsageError("give --csv or --json, not both")
    if polls is not None and interval is None:
        raise UsageError("--count N counts polls: give --interval S with it")
    if interval is not None:
        raw.check_poll(interval, polls)
    raw.decode(start, [], kind, word_order)  # refuses a bad --type or --word-order before the port opens
    if fc not in raw.READ_FUNCTIONS:
        raise UsageError(f"--fc {fc}: reads are --fc 1 (coils), 2 (discrete inputs), 3 (holding) or 4 (input)")
    if fc in raw.BIT_FUNCTIONS and (kind != "uint16" or word_order != "big"):
        raise UsageError(f"--fc {fc} reads bits: --type and --word-order are for registers")
    typed = kind != "uint16" or word_order != "big"
    interrupted = False
    with drive(ctx) as d:
        if interval is None:
            values = raw.read_values(d, start, count, kind, word_order, fc)
            owners = [raw.owner(d, v.address) if fc == 3 else None for v in values]  # the profile maps FC03 only
        else:
            try:
                _show_polls(
                    raw.poll(d, start, count, kind, word_order, interval=interval, polls=polls, fc=fc), as_csv, as_json
                )
            except KeyboardInterrupt:
                interrupted = True
    if interrupted:
        raise typer.Exit(130)
    if interval is not None:
        return
    if as_csv:
        _show_csv(values, owners, kind)
    elif as_json:
        emit_json([_value_json(v, e, kind, typed) for v, e in zip(values, owners, strict=True)])
    else:
        _show_table(values, owners, kind, typed)


def _value_json(v: raw.Value, e: Entry | None, kind: str, typed: bool) -> dict[str, object]:
    if typed:
        return {"address": v.address, "type": kind, "value": v.value, "words": list(v.words), "entry": _code(e)}
    w = v.words[0]
    return {"address": v.address, "value": w, "signed": w - 0x10000 if w >= 0x8000 else w, "entry": _code(e)}


def _code(e: Entry | None) -> str | None:
    return e.code if e else None


def _hex(words: tuple[int, ...]) -> str:
    return " ".join(f"0x{w:04X}" for w in words)


def _show_table(values: list[raw.Value], owners: list[Entry | None], kind: str, typed: bool) -> None:
    if typed:
        t = table("Address", "Hex", kind, "Registers", "Entry")
        for v, e in zip(values, owners, strict=True):
            t.add_row(str(v.address), f"0x{v.address:04X}", _number(v.value), _hex(v.words), _entry(e))
    else:
        t = table("Address", "Hex", "Value", "Signed", "Hex value", "Entry")
        for v, e in zip(values, owners, strict=True):
            w = v.words[0]
            t.add_row(
                str(v.address),
                f"0x{v.address:04X}",
                str(w),
                str(w - 0x10000 if w >= 0x8000 else w),
                _hex(v.words),
                _entry(e),
            )
    out.print(t)


def _number(value: int | float) -> str:
    """An integer in full; a float32 to the 7 significant digits it holds."""
    return f"{value:.7g}" if isinstance(value, float) else str(value)


def _entry(e: Entry | None) -> str:
    return f"{e.code} {e.name}" if e else ""


def _show_csv(values: list[raw.Value], owners: list[Entry | None], kind: str) -> None:
    w = csv.writer(sys.stdout, lineterminator="\n")
    w.writerow(["address", "type", "value", "registers", "entry"])
    for v, e in zip(values, owners, strict=True):
        w.writerow([v.address, kind, v.value, _hex(v.words), _code(e) or ""])


def _show_polls(polls: Iterator[tuple[float, list[raw.Value]]], as_csv: bool, as_json: bool) -> None:
    """One row per poll: seconds since the first, then each value (columns named by address)."""
    writer = csv.writer(sys.stdout, lineterminator="\n") if as_csv else None
    for n, (at, values) in enumerate(polls):
        if as_json:
            emit_json_line({"t": round(at, 3), "values": {str(v.address): v.value for v in values}})
        elif writer is not None:
            if n == 0:
                writer.writerow(["t", *(f"0x{v.address:04X}" for v in values)])
            writer.writerow([f"{at:.3f}", *(v.value for v in values)])
            sys.stdout.flush()
        else:
            if n == 0:
                header = " ".join(f"{f'0x{v.address:04X}':>12}" for v in values)
                out.print(f"{'t (s)':>8} {header}", markup=False)
            out.print(f"{at:8.3f} " + " ".join(f"{_number(v.value):>12}" for v in values), markup=False)


@app.command("write")
def write(
    ctx: typer.Context,
    assignment: str = typer.Argument(
        ..., help="ADDR=VALUE[,VALUE...]: decimal or hex, e.g. 0x2004=300, or 0x2100=400,401 for FC16."
    ),
    fc: int | None = typer.Option(
        None, "--fc", help="5 one coil, 15 coils (values 0/1); 6 one register, 16 several (the default by count)."
    ),
    yes: bool = typer.Option(False, "--yes", "-y", help="Do not ask (real drives only; the simulator never asks)."),
    as_json: bool = JSON_OPT,
) -> None:
    """Write one register (FC06), or several from ADDR on (FC16), or coils (--fc 5, 15), and read them back. No
    profile check: the drive is the only judge."""
    if "=" not in assignment:
        raise UsageError(f"'{assignment}' is not ADDR=VALUE")
    left, _, right = assignment.partition("=")
    address, values = raw.parse_address(left), [raw.parse_word(v) for v in right.split(",")]
    coils = _check_write_fc(fc, values)
    simulated = resolved(ctx).simulated
    last = address + len(values) - 1
    with drive(ctx) as d:
        entry = raw.owner(d, address)
        span = f"{address}" if len(values) == 1 else f"{address}..{last}"
        what = (
            f"{'coil' if coils else 'register'}{'s' if len(values) > 1 else ''} {span} (0x{address:04X}"
            + (f", {entry.code} {entry.name}" if entry else "")
            + ")"
        )
        shown = ",".join(str(v) for v in values)
        if not simulated and not confirm(f"Write {shown} to {what} of unit {d.unit}?", yes):
            raise ServoError("cancelled: nothing was written")
        if coils:
            back = raw.write_coils(d, address, values, many=fc == 15)
        else:
            back = raw.write_registers(d, address, values)
    if as_json:
        value: object = back[0] if len(back) == 1 else back
        emit_json({"address": address, "value": value, "entry": _code(entry), "verified": True})
    else:
        said = ", ".join(str(b) if coils else f"{b} (0x{b:04X})" for b in back)
        out.print(f"{what}: {said}, verified by read-back", markup=False)


def _check_write_fc(fc: int | None, values: list[int]) -> bool:
    """Whether the write is of coils; UsageError for a function that cannot carry these values."""
    if fc not in (None, 5, 6, 15, 16):
        raise UsageError(f"--fc {fc}: writes are --fc 5 (one coil), 6 (one register), 15 (coils), 16 (registers)")
    if fc in (5, 6) and len(values) != 1:
        raise UsageError(f"--fc {fc} writes one value, not {len(values)}: give --fc {15 if fc == 5 else 16}")
    if fc == 16 and len(values) == 1:
        raise UsageError("--fc 16 with one register: give two or more values, or --fc 6")
    if fc in (5, 15) and (bad := [v for v in values if v not in (0, 1)]):
        raise UsageError(f"a coil is 0 or 1, not {bad[0]}")
    return fc in (5, 15)
