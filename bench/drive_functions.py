"""Do the drive's own functions leave machines better, and never worse? (issue 34 item 6)

Over seeded machines on virtual time at each profile's factory line speed, `tune friction` (DSX7E, SDC) and
`tune notch` (IS620P: the drive's adaptive notch; SD25: at a peak the line resolves) run as the CLI runs them
(score before with 3 runs, set up, score after, keep only beyond the spread) and each machine is counted:

  improved   the change was kept: its judged figures improved beyond their spread
  unchanged  nothing written (nothing to compensate, no resolvable resonance) or put back (no improvement)
  worse      the drive left holding a change whose judged figures got worse (must be 0)
  could-help machines with something to fix (friction >= 2 % of rated torque; a 50-65 Hz resonance under a
             45-50 Hz loop) and the share improved
  no-help    machines with nothing to fix (friction below 0.5 %; a rigid load) and the share left unchanged
  alarm      runs the drive stopped with an alarm (the loop as tuned cannot carry the machine; put back)

Run: python bench/drive_functions.py [--quick] [--seeds N] [--functions friction,notch]
"""

from __future__ import annotations

import argparse
import os
import random
import tempfile
import time
from collections import Counter

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.codec import eng_to_raw
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning import drive_functions as functions
from servotool.tuning import score as scoring

FACTORY_BAUD = {"sd25": 9600, "sdc": 9600, "is620p": 57600, "dsx7e": 115200}
PROFILES = {"friction": ("dsx7e", "sdc"), "notch": ("is620p", "sd25")}


def machine(rng: random.Random, function: str, helpful: bool) -> dict[str, float]:
    """A seeded machine. Friction, helpful: friction worth compensating, else none to speak of. Notch, helpful: a
    two-mass load (ratio 5) resonating at 50-65 Hz under a 45-50 Hz speed loop, else the same loop on a rigid load."""
    if function == "notch":
        return {
            "load_ratio": 5.0,
            "friction": rng.uniform(0.0, 0.04),
            "noise": rng.choice((0.0002, 0.001)),
            "resonance_hz": rng.uniform(50.0, 65.0) if helpful else 0.0,
            "resonance_damping": rng.uniform(0.01, 0.03),
            "seed": rng.randrange(1000),
            "gain_hz": rng.choice((45.0, 50.0)),
        }
    return {
        "load_ratio": rng.choice((0.5, 2.0, 5.0, 10.0)),
        "friction": rng.uniform(0.02, 0.12) if helpful else rng.uniform(0.0, 0.004),
        "viscous": rng.uniform(0.0, 0.0003),
        "noise": rng.choice((0.0002, 0.001)),
        "seed": rng.randrange(1000),
    }


def run_one(function: str, profile_id: str, settings: dict[str, float]) -> str:
    p = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim = build_drive(p, 1, clock, persist=False)
    make_motion_setup(sim)
    gain_hz = settings.pop("gain_hz", None)
    sim.settings.update(settings)
    sim.firmware.reconfigure()
    d = Drive(VirtualLink([sim], clock, FACTORY_BAUD[profile_id]), p, 1)
    d.dead_man_waived = True
    if gain_hz is not None:  # the loop the machine is tuned to, at its true inertia ratio
        for role, value in (
            ("inertia_ratio", p.param_from_load_ratio(settings["load_ratio"])),
            ("speed_loop_gain", gain_hz),
        ):
            entry = p.need_role(role, "bench")
            d.write_raw(entry, eng_to_raw(entry, value))
    motion = scoring.motion_for(2.0)
    try:
        before = scoring.measure(d, motion, 3, clock)
        if function == "friction":
            trial = functions.friction_trial(d, motion, before, clock)
        elif p.role("adaptive_notch") is not None:
            trial = functions.adaptive_notch_trial(d, motion, before, clock)
        else:
            trial = functions.notch_trial(d, before)
        trial = functions.judged_trial(d, trial, motion, 3, clock=clock)
    except ServoError:
        return "alarm"
    if trial.kept and trial.verdict == "worse":
        return "worse"
    return "improved" if trial.kept else "unchanged"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 machines per profile and kind")
    ap.add_argument("--seeds", type=int, default=10, help="machines per profile and kind (helpful / no help)")
    ap.add_argument("--functions", default="friction,notch")
    args = ap.parse_args()
    os.environ["SERVOTOOL_SIM_DIR"] = tempfile.mkdtemp(prefix="servotool-bench-")
    seeds = 4 if args.quick else args.seeds
    t0 = time.monotonic()
    print(
        f"{'function':9} {'profile':7} {'kind':9} {'machines':>8} {'improved':>8} {'unchanged':>9} {'worse':>5} "
        f"{'alarm':>5}"
    )
    worse_total = 0
    for function in args.functions.split(","):
        for profile_id in PROFILES[function]:
            for helpful in (True, False):
                rng = random.Random(f"{function}-{profile_id}-{helpful}")
                counts = Counter(run_one(function, profile_id, machine(rng, function, helpful)) for _ in range(seeds))
                worse_total += counts["worse"]
                kind = "could-help" if helpful else "no-help"
                print(
                    f"{function:9} {profile_id:7} {kind:9} {seeds:8d} {counts['improved'] / seeds:8.0%} "
                    f"{counts['unchanged'] / seeds:9.0%} {counts['worse']:5d} {counts['alarm']:5d}"
                )
    print(f"left worse: {worse_total} (must be 0); {time.monotonic() - t0:.0f} s wall, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
