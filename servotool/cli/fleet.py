"""`servotool fleet backup|drift|apply INVENTORY`: every bus of an inventory at once, a worker per bus, one
progress display, one summary table (or JSON)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from servotool.cli.common import JSON_OPT
from servotool.cli.render import Verbosity, emit_json, err, info, out, table
from servotool.errors import UsageError
from servotool.words import count

if TYPE_CHECKING:
    from servotool.fleet.inventory import Inventory
    from servotool.fleet.runner import Event, FleetResult

app = typer.Typer(no_args_is_help=True, help="Back up, compare and set the drives of many machines at once.")

INVENTORY = typer.Argument(..., help="Inventory file: machines, their buses (ports), units, profiles, golden files.")
JOBS = typer.Option(None, "--jobs", "-j", help="At most this many buses at once (default: all).")


@app.command("backup")
def backup_cmd(
    inventory: Path = INVENTORY,
    output: Path = typer.Option(
        ..., "--output", "-o", help="Folder of snapshots: OUT/MACHINE/BUS-unitN-PROFILE.yaml, replaced in place."
    ),
    jobs: int = JOBS,
    as_json: bool = JSON_OPT,
) -> None:
    """Snapshot every drive (no time stamp: a folder for version control); 'unchanged' when the file was."""
    from servotool.fleet.actions import Backup

    if output.exists() and not output.is_dir():
        raise UsageError(f"{output} is not a folder")
    _run(inventory, Backup(output), jobs, as_json, differ=())


@app.command("drift")
def drift_cmd(
    inventory: Path = INVENTORY,
    against: Path = typer.Option(
        None, "--against", help="Compare with the snapshots `fleet backup` wrote in this folder, not the golden files."
    ),
    jobs: int = JOBS,
    as_json: bool = JSON_OPT,
) -> None:
    """Compare every drive with its golden file; writes nothing. Exit 0 all equal, 1 some differ, 5 some failed."""
    from servotool.fleet.actions import DIFFERS, Drift

    if against is not None and not against.is_dir():
        raise UsageError(f"--against {against}: no such folder")
    _run(inventory, Drift(against), jobs, as_json, differ=(DIFFERS,), golden=against is None)


@app.command("apply")
def apply_cmd(
    inventory: Path = INVENTORY,
    check: bool = typer.Option(False, "--check", help="Write nothing: say what would change (exit 1 if anything)."),
    jobs: int = JOBS,
    as_json: bool = JSON_OPT,
) -> None:
    """Bring every drive to its golden file, writing only what differs; a failed drive is rolled back."""
    from servotool.fleet.actions import Apply
    from servotool.ops.apply import WOULD_CHANGE

    _run(inventory, Apply(check), jobs, as_json, differ=(WOULD_CHANGE,), golden=True)


def _run(
    path: Path, action: Any, jobs: int | None, as_json: bool, differ: tuple[str, ...], golden: bool = False
) -> None:
    """Load the inventory (and check the golden files), run, show the table or JSON; exit as runner.exit_status."""
    from servotool.fleet import inventory, runner

    if jobs is not None and jobs < 1:
        raise UsageError(f"--jobs {jobs}: give 1 or more")
    found = inventory.load(path)
    if golden:
        _check_golden(found)
    stop = threading.Event()
    with _display(found, enabled=not as_json) as show:
        result = runner.run(found, action, jobs=jobs, events=show, stop=stop)
    if as_json:
        emit_json(_json(path, result))
    else:
        _summary(result)
    status = runner.exit_status(result, differ)
    if status:
        raise typer.Exit(status)


def _check_golden(found: Inventory) -> None:
    """Every golden file is there and reads as a settings file or a backup, before any bus is opened."""
    from servotool.model.loader import load_profile
    from servotool.ops import desired

    for golden in sorted({t.golden for b in found.buses for t in b.targets if t.golden is not None}):
        if not golden.is_file():
            raise UsageError(f"{found.path}: golden file {golden} does not exist")
        named = desired.profile_named(golden)
        desired.load(golden, load_profile(named) if named else None)


@contextmanager
def _display(found: Inventory, enabled: bool) -> Iterator[Callable[[Event], None]]:
    """One progress display for every bus: a row per bus on a terminal, else a line per drive as it ends (none
    with --quiet or --json). Events come from the workers' threads."""
    lock = threading.Lock()
    if not enabled or Verbosity.level < 0:
        yield lambda _e: None
        return
    if not err.is_terminal:

        def line(e: Event) -> None:
            with lock:
                if e.kind == "notice":
                    info(f"{e.spec.machine}/{e.spec.name}: {e.text}")
                elif e.kind == "done" and e.outcome is not None:
                    o = e.outcome
                    info(f"{o.machine}/{o.bus} unit {o.unit}: {o.status}: {o.detail}")

        yield line
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as bar:
        tasks = {id(b): bar.add_task(f"{b.machine}/{b.name}", total=len(b.targets)) for b in found.buses}

        def update(e: Event) -> None:
            task = tasks[id(e.spec)]
            with lock:
                if e.kind == "notice":
                    bar.console.print(f"{e.spec.machine}/{e.spec.name}: {e.text}", markup=False)
                elif e.kind == "drive":
                    bar.update(task, description=f"{e.spec.machine}/{e.spec.name} unit {e.unit}")
                elif e.kind == "done":
                    bar.advance(task)
                elif e.kind == "bus_done":
                    bar.update(task, description=f"{e.spec.machine}/{e.spec.name} done")

        yield update


def _summary(result: FleetResult) -> None:
    t = table("Machine", "Bus", "Unit", "Profile", "Status", "Detail", "Time")
    for d in result.drives:
        t.add_row(
            d.machine,
            d.bus,
            str(d.unit),
            d.profile or "",
            d.status.upper() if d.failed else d.status,
            d.detail,
            f"{d.seconds:.1f} s",
        )
    out.print(t)
    counts = ", ".join(f"{n} {status}" for status, n in result.counts().items())
    buses = len(result.buses)
    out.print(
        f"{result.action}: {count(len(result.drives), 'drive')} on {count(buses, 'bus', 'buses')} in "
        f"{result.seconds:.1f} s: {counts}",
        markup=False,
    )


def _json(path: Path, result: FleetResult) -> dict[str, Any]:
    return {
        "action": result.action,
        "inventory": str(path),
        "summary": result.counts(),
        "time": {"value": round(result.seconds, 3), "unit": "s"},
        "buses": [b.as_json() for b in result.buses],
        "drives": [d.as_json() for d in result.drives],
    }
