"""`servotool alarm [show|clear|history]`."""

from __future__ import annotations

import typer

from servotool.cli.common import JSON_OPT, drive
from servotool.cli.render import emit_json, out, table
from servotool.ops import alarms

app = typer.Typer(help="Show, clear and list the drive's alarms.")


def _show(ctx: typer.Context, as_json: bool) -> None:
    with drive(ctx) as d:
        state = alarms.current(d)
    if as_json:
        emit_json(state.as_json())
    elif state.active:
        out.print(
            f"ALARM {state.display}: {state.name}"
            + ("" if state.clearable is None else f" ({'clearable' if state.clearable else 'not clearable'})"),
            markup=False,
        )
    else:
        out.print("no alarm", markup=False)


@app.callback(invoke_without_command=True)
def main(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Without a sub-command: show the current alarm."""
    if ctx.invoked_subcommand is None:
        _show(ctx, as_json)


@app.command("show")
def show(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """The current alarm (exit 0 either way; see --json 'active')."""
    _show(ctx, as_json)


@app.command("clear")
def clear(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Reset the alarm through the profile's alarm-reset function; exit 3 if it stays active."""
    with drive(ctx) as d:
        before = alarms.current(d)
        after = alarms.clear(d)
    if as_json:
        emit_json({"before": before.as_json(), "after": after.as_json()})
    else:
        out.print(f"cleared {before.display} {before.name}" if before.active else "no alarm was active", markup=False)


@app.command("history")
def history(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Previous alarms, most recent first; the first is marked active while it is the drive's current alarm."""
    with drive(ctx) as d:
        items = alarms.history(d)
    if as_json:
        emit_json([i.as_json() for i in items])
        return
    t = table("#", "Code", "Name", "Now")
    for n, item in enumerate(items, start=1):
        t.add_row(str(n), item.display, item.name, "active" if item.active else "")
    out.print(t)
