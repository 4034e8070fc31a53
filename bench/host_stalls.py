"""Identification on a host that stalls (a loaded laptop, a scheduler tick, a USB adapter's latency timer): does the
stop guard keep the axis inside its travel?

Each request, with a given probability, waits a uniform 10 ms..max before it is sent (sim.virtual.HostStalls,
seeded), on virtual time, through tune_inertia as the CLI runs it (a dry run). Every outcome is counted: identified,
refused (too uncertain for the shorter moves the guard allows: honest), or stopped at the travel limit (the guard
failed to foresee the stall: the axis went past --travel). Target: no travel trips where the stall has been seen
before (a stall longer than any before can still surprise the guard, which then stops the motion).

Run: python bench/host_stalls.py [--machines 20]
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections import Counter

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import HostStalls, VirtualLink, make_motion_setup
from servotool.tuning.errors import TravelExceeded
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import TuneRequest, tune_inertia

ROWS = [("dsx7e", 115200), ("dsx7e", 19200), ("is620p", 57600), ("sdc", 19200), ("sd25", 19200)]
STALLS = [(0.0, 0.05), (0.02, 0.05), (0.05, 0.03), (0.005, 0.1)]
LOADS = [0.0, 1.0, 4.0, 10.0, 37.0]


def outcome(profile_id: str, baud: int, ratio: float, seed: int, stalls: HostStalls) -> str:
    profile = load_profile(profile_id)
    clock = VirtualClock(1000.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(load_ratio=ratio, seed=seed)
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    drive = Drive(VirtualLink([sim], clock, baud, stalls), profile, 1)
    drive.dead_man_waived = True
    try:
        tune_inertia(drive, TuneRequest(travel_rev=2.0, dry_run=True), clock=clock)
    except TravelExceeded:
        return "travel trip"
    except IdentificationRefused:
        return "refused"
    except ServoError as exc:
        return f"failed: {exc}"[:60]
    return "identified"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--machines", type=int, default=20, help="machines per cell (loads x seeds)")
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    machines = [(LOADS[n % len(LOADS)], n // len(LOADS) + 1) for n in range(args.machines)]
    print(f"{'profile':>7} {'baud':>6} {'stall rate':>10} {'max ms':>6}  identified  refused  travel trips")
    for pid, baud in ROWS:
        for rate, max_s in STALLS:
            counts = Counter(outcome(pid, baud, ratio, seed, HostStalls(rate, max_s, seed)) for ratio, seed in machines)
            print(
                f"{pid:>7} {baud:>6} {rate:>10.1%} {max_s * 1000:>6.0f}  {counts['identified']:>10} "
                f"{counts['refused']:>8} {counts['travel trip']:>13}",
                flush=True,
            )
            for other in set(counts) - {"identified", "refused", "travel trip"}:
                print(f"{'':>34}{counts[other]} x {other}")


if __name__ == "__main__":
    main()
