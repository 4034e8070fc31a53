"""Does `tune inertia` keep every motion route stable, whatever the load? (issue 16 item 3)

IS620P's segment route ends each move in the drive's position hold; with the factory gains at the factory inertia
ratio a heavy load made that hold swing with growing amplitude (the speed loop's gain comes from the configured
ratio, the position loop and the speed integral stay fast) until the travel guard stopped it. This sweep runs
`tune inertia` (a dry run, as the CLI's default motion) on every profile at its factory line speed over loads
0-50 with friction and noise, on virtual time, and counts per profile and load:

  peak   the largest |true motor speed| seen at any read, over the largest speed servotool commanded (a loop
         that swings shows as peaks far beyond 1; ~1.0-1.2 is a ramp's normal overshoot)
  grow   runs whose peak exceeds GROWTH (1.3x)
  trip   runs stopped by the travel guard ("travel limit ... reached")
  alarm  runs the drive stopped with an alarm (following error, overload, overspeed)
  refused  other refusals (the estimate not trusted)

With --jog, a 1 s JOG (as `servotool jog` runs it) at 100 and 1000 rpm instead of the identification: peak is the
largest |true speed| over the JOG speed.

Run: python bench/hold_stability.py [--quick] [--profiles is620p,sd25] [--seeds N] [--baud 115200] [--jog]
"""

from __future__ import annotations

import argparse
import itertools
import os
import tempfile
from dataclasses import dataclass, field

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning.errors import TravelExceeded
from servotool.tuning.stable_hold import guarded_jogger
from servotool.tuning.tune import TuneRequest, tune_inertia

FACTORY_BAUD = {"sd25": 9600, "sdc": 9600, "is620p": 57600, "dsx7e": 115200}
GROWTH = 1.3


@dataclass
class Run:
    """One `tune inertia` on one simulated machine."""

    peak: float = 0.0  # max |true speed| / max |commanded speed|
    outcome: str = "ok"  # ok | trip | alarm | refused
    reason: str = ""
    error_pct: float | None = None  # |ratio error| / (1 + ratio), accepted runs


@dataclass
class Cell:
    runs: list[Run] = field(default_factory=list)

    def count(self, outcome: str) -> int:
        return sum(r.outcome == outcome for r in self.runs)

    @property
    def grown(self) -> int:
        return sum(r.peak > GROWTH for r in self.runs)


def machine(
    profile_id: str, ratio: float, friction: float, noise: float, seed: int, baud: int | None = None
) -> tuple[Drive, VirtualClock, dict[str, float]]:
    """A simulated drive with its motion setup on virtual time, and the largest |true speed| and |commanded
    speed| seen at any read so far."""
    profile = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(load_ratio=ratio, friction=friction, noise=noise, seed=seed)
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    drive = Drive(VirtualLink([sim], clock, baud or FACTORY_BAUD[profile_id]), profile, 1)
    drive.dead_man_waived = True  # SD25 and SDC have no dead-man route; this is about the loops
    plant = sim.firmware.plant
    seen = {"speed": 0.0, "command": 0.0}

    def watch(_sim: object) -> None:
        seen["speed"] = max(seen["speed"], abs(plant.true_speed_rpm))
        seen["command"] = max(seen["command"], abs(plant.target_rpm))

    sim.on_read.append(watch)
    return drive, clock, seen


def run_once(profile_id: str, ratio: float, friction: float, noise: float, seed: int, baud: int | None = None) -> Run:
    """`tune inertia` (dry run) on one machine, watching the true speed at every read."""
    drive, clock, seen = machine(profile_id, ratio, friction, noise, seed, baud)
    run = Run()
    try:
        res = tune_inertia(drive, TuneRequest(dry_run=True), clock=clock)
        run.error_pct = abs(res.ratio - ratio) / (1.0 + ratio) * 100.0
    except TravelExceeded as exc:
        run.outcome, run.reason = "trip", str(exc).split(":")[0]
    except ServoError as exc:
        text = str(exc)
        run.outcome = "alarm" if "alarm" in text else "refused"
        run.reason = text.split(": ", 1)[-1][:60] if "refused" in text else text[:60]
    run.peak = seen["speed"] / seen["command"] if seen["command"] > 0 else 0.0
    return run


def run_jog(
    profile_id: str, ratio: float, friction: float, noise: float, seed: int, speed_rpm: float, baud: int | None = None
) -> Run:
    """A 1 s JOG at speed_rpm as `servotool jog` runs it (guarded_jogger), watching the true speed."""
    drive, clock, seen = machine(profile_id, ratio, friction, noise, seed, baud)
    run = Run()
    try:
        jogger = guarded_jogger(drive, clock)
        jogger.run(jogger.plan(speed_rpm, 1.0))
    except ServoError as exc:
        run.outcome = "alarm" if "alarm" in str(exc) else "refused"
        run.reason = str(exc)[:60]
    run.peak = seen["speed"] / speed_rpm
    return run


def sweep(
    profiles: list[str],
    loads: list[float],
    frictions: list[float],
    noises: list[float],
    seeds: int,
    baud: int | None = None,
    jog: bool = False,
) -> dict[tuple[str, float], Cell]:
    cells: dict[tuple[str, float], Cell] = {}
    for pid, load in itertools.product(profiles, loads):
        cell = cells.setdefault((pid, load), Cell())
        for n, (fr, nz, seed) in enumerate(itertools.product(frictions, noises, range(1, seeds + 1))):
            if jog:
                cell.runs += [run_jog(pid, load, fr, nz, seed + 7 * n, rpm, baud) for rpm in (100.0, 1000.0)]
            else:
                cell.runs.append(run_once(pid, load, fr, nz, seed + 7 * n, baud))
    return cells


def print_table(cells: dict[tuple[str, float], Cell]) -> None:
    print(
        f"{'profile':>7} {'load':>5} {'runs':>4} {'peak max':>8} {'peak med':>8} {'grow':>4} {'trip':>4} "
        f"{'alarm':>5} {'refused':>7} {'err% max':>8}  reasons"
    )
    for (pid, load), cell in cells.items():
        peaks = sorted(r.peak for r in cell.runs)
        errs = [r.error_pct for r in cell.runs if r.error_pct is not None]
        reasons = sorted({r.reason for r in cell.runs if r.reason})
        print(
            f"{pid:>7} {load:>5.0f} {len(cell.runs):>4} {peaks[-1]:>8.2f} {peaks[len(peaks) // 2]:>8.2f} "
            f"{cell.grown:>4} {cell.count('trip'):>4} {cell.count('alarm'):>5} {cell.count('refused'):>7} "
            f"{(max(errs) if errs else float('nan')):>8.2f}  {'; '.join(reasons)[:90]}",
            flush=True,
        )
    runs = [r for c in cells.values() for r in c.runs]
    print(
        f"total: {len(runs)} runs, peak > {GROWTH}x: {sum(r.peak > GROWTH for r in runs)}, travel trips: "
        f"{sum(r.outcome == 'trip' for r in runs)}, alarms: {sum(r.outcome == 'alarm' for r in runs)}, "
        f"refused: {sum(r.outcome == 'refused' for r in runs)}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer loads, one friction, one seed")
    ap.add_argument("--profiles", default=",".join(FACTORY_BAUD), help="comma-separated profile ids")
    ap.add_argument("--seeds", type=int, default=None, help="seeds per (friction, noise)")
    ap.add_argument("--baud", type=int, default=None, help="line speed (default: each drive's factory setting)")
    ap.add_argument("--jog", action="store_true", help="JOGs at 100 and 1000 rpm instead of the identification")
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    loads = [0.0, 5.0, 20.0, 37.0, 49.0] if args.quick else [0.0, 2.0, 5.0, 10.0, 20.0, 30.0, 37.0, 43.0, 50.0]
    frictions = [0.05] if args.quick else [0.02, 0.1, 0.3]
    noises = [0.002] if args.quick else [0.002, 0.01]
    seeds = args.seeds if args.seeds is not None else (1 if args.quick else 2)
    print_table(sweep([p for p in args.profiles.split(",") if p], loads, frictions, noises, seeds, args.baud, args.jog))


if __name__ == "__main__":
    main()
