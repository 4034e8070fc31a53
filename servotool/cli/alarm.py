"""`servotool alarm [show|clear|history]`."""

from __future__ import annotations

import typer

from servotool.cli.common import JSON_OPT, drive
from servotool.cli.render import emit_json, out, table, wrap
from servotool.ops import alarms
from servotool.ops.alarms import AlarmHistory, AlarmState, Recorded

app = typer.Typer(help="Show, clear and list the drive's alarms.")


def _headline(state: AlarmState) -> str:
    clearable = "" if state.clearable is None else f" ({'clearable' if state.clearable else 'not clearable'})"
    return f"ALARM {state.display}: {state.name}{clearable}"


def causes_text(state: AlarmState) -> list[str]:
    """The manual's causes and remedies of an alarm, a cause and its remedy on two lines, fitted to the width; or
    what the manual gives instead."""
    note = state.manual
    if note is None:
        return []
    if not note.causes:
        return [wrap(f"  causes: {note.note}", hanging="    ")]
    lines = [wrap(f"  causes and remedies (manual {note.source}):", hanging="    ")]
    for c in note.causes:
        lines.append(wrap(f"- {c.cause}", indent="    "))
        lines.append(wrap(f"-> {c.remedy}", indent="      ", hanging="   "))
    return lines


def _recorded(values: tuple[Recorded, ...]) -> str:
    return ", ".join(f"{alarms.CONTEXT_WORDS[r.meaning]} {r.text}" for r in values)


def _show(ctx: typer.Context, as_json: bool) -> None:
    with drive(ctx) as d:
        state = alarms.current(d)
    if as_json:
        emit_json(state.as_json())
        return
    if not state.active:
        out.print("no alarm", markup=False)
        return
    out.print("\n".join([wrap(_headline(state)), *causes_text(state)]), markup=False)


@app.callback(invoke_without_command=True)
def main(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """Without a sub-command: show the current alarm, with the manual's causes and remedies."""
    if ctx.invoked_subcommand is None:
        _show(ctx, as_json)


@app.command("show")
def show(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """The current alarm with the manual's causes and remedies (exit 0 either way; see --json 'active')."""
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


def history_lines(h: AlarmHistory) -> list[object]:
    """The current alarm, the drive's past ones as a table (only the records that hold one), then each alarm's
    causes and remedies once."""
    shown: list[AlarmState] = []
    lines: list[object] = []
    if h.current.active:
        lines.append(wrap(_headline(h.current) + (f"; {_recorded(h.current_recorded)}" if h.current_recorded else "")))
        shown.append(h.current)
    else:
        lines.append("no alarm now")
    kept = f"the drive keeps {h.slots} past alarm{'s' if h.slots != 1 else ''} ({h.kept_in})"
    if not h.records:
        lines.append(wrap(f"no past alarm: {kept}, all empty"))
    else:
        lines.append(wrap(f"past alarms, most recent first: {kept}"))
        recorded = any(r.recorded for r in h.records)
        t = table("#", "Code", "Name", *(["Recorded"] if recorded else []))
        for r in h.records:
            name = r.alarm.name + (" (now)" if r.alarm.active else "")
            t.add_row(str(r.number), r.alarm.display, name, *([_recorded(r.recorded)] if recorded else []))
            if all(s.code != r.alarm.code for s in shown):
                shown.append(r.alarm)
        lines.append(t)
    for state in shown:
        lines.append(wrap(f"{state.display} {state.name}:"))
        lines.extend(causes_text(state))
    if h.unverified and (h.records or h.current_recorded):
        lines.append(wrap(f"unverified: {h.unverified}"))
    return lines


@app.command("history")
def history(ctx: typer.Context, as_json: bool = JSON_OPT) -> None:
    """The drive's own log of past alarms, most recent first, with what it recorded at each (speed, voltage,
    current, run time, where it keeps them) and the manual's causes and remedies."""
    with drive(ctx) as d:
        h = alarms.history(d)
    if as_json:
        emit_json(h.as_json())
        return
    for line in history_lines(h):
        out.print(line, markup=False)
