"""Do the drive's own functions leave machines better, and never worse? (issue 34 item 6)

Over seeded machines on virtual time at each profile's factory line speed, `tune friction` (DSX7E, SDC: compensation
torques; SD25: its own compensation, Po183-187, raised 50 % then 95 %) and `tune notch` (IS620P: the drive's
adaptive notch; SD25: at a peak the line resolves) run as the CLI runs them (tuning.function_run: score before with
3 runs, set up, score after, keep only beyond the spread) and each machine is counted:

  improved   the change was kept: its judged figures improved beyond their spread
  unchanged  nothing written (nothing to compensate, no resolvable resonance) or put back (no improvement)
  worse      the drive left holding a change whose judged figures got worse (must be 0)
  could-help machines with something to fix (friction 2-12 % of rated torque, --friction; a 50-65 Hz resonance
             under a 45-50 Hz loop) and the share improved
  no-help    machines with nothing to fix (friction below 0.5 %; a rigid load) and the share left unchanged
  alarm      runs the drive stopped with an alarm (the loop as tuned cannot carry the machine; put back)

With --real-time PROFILES the rows of those profiles run instead as users run them: per machine its own state folder,
`sim config`, the profile's motion setup stored and power-cycled, `sim serve` on TCP (its line at the profile's factory
speed), then `servotool tune friction|notch --yes --json` as a separate process; the process's wall time is printed.

Run: python bench/drive_functions.py [--quick] [--seeds N] [--functions friction,notch] [--friction 0.02,0.12]
     [--profiles sd25] [--real-time sd25] [--port-base 24000]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.codec import eng_to_raw
from servotool.model.loader import load_profile
from servotool.model.profile import Entry, Profile
from servotool.model.setup import requirements
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning import function_run
from servotool.tuning import score as scoring

FACTORY_BAUD = {"sd25": 9600, "sdc": 9600, "is620p": 57600, "dsx7e": 115200}
PROFILES = {"friction": ("dsx7e", "sdc", "sd25"), "notch": ("is620p", "sd25")}
MACHINE_OPTIONS = ("load_ratio", "friction", "viscous", "noise", "seed", "resonance_hz", "resonance_damping")


def machine(
    rng: random.Random, function: str, helpful: bool, friction: tuple[float, float] = (0.02, 0.12)
) -> dict[str, float]:
    """A seeded machine. Friction, helpful: Coulomb friction in the `friction` band, else none to speak of. Notch,
    helpful: a two-mass load (ratio 5) resonating at 50-65 Hz under a 45-50 Hz speed loop, else the same loop on a
    rigid load."""
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
        "friction": rng.uniform(*friction) if helpful else rng.uniform(0.0, 0.004),
        "viscous": rng.uniform(0.0, 0.0003),
        "noise": rng.choice((0.0002, 0.001)),
        "seed": rng.randrange(1000),
    }


def commissioned(p: Profile, load_ratio: float, gain_hz: float | None) -> list[tuple[Entry, float]]:
    """The loop of a commissioned machine: its true inertia ratio where the profile maps one (SD25 section 9.6,
    L8020: friction compensation wants Po013 'set as correctly as possible'), and the notch machines' speed-loop
    gain (gain_hz)."""
    found = [(e, p.param_from_load_ratio(load_ratio)) for e in [p.role("inertia_ratio")] if e is not None]
    return found + ([(p.need_role("speed_loop_gain", "bench"), gain_hz)] if gain_hz is not None else [])


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
    for entry, value in commissioned(p, settings["load_ratio"], gain_hz):
        d.write_raw(entry, eng_to_raw(entry, value))
    try:  # the one use case tune and plans run (tuning.function_run): its method chosen by the profile
        trial = function_run.run_function(d, function, scoring.planned(d, scoring.motion_for(2.0)), 3, clock=clock)
    except ServoError:
        return "alarm"
    if trial.kept and trial.verdict == "worse":
        return "worse"
    return "improved" if trial.kept else "unchanged"


def run_real_time(function: str, profile_id: str, settings: dict[str, float], port: int) -> tuple[str, float]:
    """One machine as a user meets it, through the CLI on `sim serve` in real time: (outcome, tune's wall seconds)."""
    folder = Path(tempfile.mkdtemp(prefix="servotool-bench-fn-"))
    env = {**os.environ, "SERVOTOOL_SIM_DIR": str(folder / "sim"), "SERVOTOOL_BACKUP_DIR": str(folder / "bk")}
    env |= {"SERVOTOOL_CACHE_DIR": str(folder / "cache"), "SERVOTOOL_CONFIG": str(folder / "none.yaml")}
    env.pop("SERVOTOOL_SIM_LINE_BAUD", None)

    def cli(*args: str, timeout: float = 60) -> subprocess.CompletedProcess[str]:
        cmd = [sys.executable, "-m", "servotool", *args]
        return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout, check=False)

    gain_hz = settings.pop("gain_hz", None)
    machine_args = [a for k in MACHINE_OPTIONS if k in settings for a in (f"--{k.replace('_', '-')}", str(settings[k]))]
    p = load_profile(profile_id)
    setup = [a for r in requirements(p) for a in r.assignments()]
    setup += [f"{entry.code}={value:g}" for entry, value in commissioned(p, settings["load_ratio"], gain_hz)]
    steps = [("-P", profile_id, "sim", "config", *machine_args)]
    if setup:
        steps += [("--port", "sim", "-P", profile_id, "param", "set", "--save", *setup)]
        steps += [("--port", "sim", "-P", profile_id, "sim", "reset", "--power-cycle")]
    for step in steps:
        if (r := cli(*step)).returncode != 0:
            raise SystemExit(f"{' '.join(step)}: exit {r.returncode}: {r.stderr.strip()[-300:]}")
    serve = [sys.executable, "-m", "servotool", "sim", "serve", "--port", f"tcp://127.0.0.1:{port}", "-P", profile_id]
    proc = subprocess.Popen(serve, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stderr is not None
        banner = proc.stderr.readline()
        if not (found := re.search(r"serving on (tcp://\S+)", banner)):
            raise SystemExit(f"sim serve did not start: {banner.strip()}")
        t0 = time.monotonic()
        tune = ("--port", found.group(1), "-P", profile_id, "tune", function, "--yes", "--no-dead-man", "--json")
        r = cli(*tune, "--repeats", "3", timeout=900)
        wall = time.monotonic() - t0
    finally:
        proc.terminate()
        proc.wait(timeout=30)
    if r.returncode != 0 and not r.stdout.strip():
        return ("alarm" if "alarm" in r.stderr.lower() else f"error: {r.stderr.strip()[-200:]}"), wall
    data = json.loads(r.stdout)
    if data["kept"] and data["verdict"] == "worse":
        return "worse", wall
    return ("improved" if data["kept"] else "unchanged"), wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 machines per profile and kind")
    ap.add_argument("--seeds", type=int, default=10, help="machines per profile and kind (helpful / no help)")
    ap.add_argument("--functions", default="friction,notch")
    ap.add_argument("--profiles", default="", help="only these profiles (comma-separated; default: all)")
    ap.add_argument("--friction", default="0.02,0.12", help="could-help band of Coulomb friction, of rated torque")
    ap.add_argument("--real-time", default="", metavar="PROFILES", help="profiles run through the CLI in real time")
    ap.add_argument("--port-base", type=int, default=24000, help="TCP port of `sim serve` in real time")
    args = ap.parse_args()
    real_time = {x for x in args.real_time.split(",") if x}
    low, high = (float(x) for x in args.friction.split(","))
    os.environ["SERVOTOOL_SIM_DIR"] = tempfile.mkdtemp(prefix="servotool-bench-")
    seeds = 4 if args.quick else args.seeds
    t0 = time.monotonic()
    print(
        f"{'function':9} {'profile':7} {'kind':10} {'time':7} {'machines':>8} {'improved':>8} {'unchanged':>9} "
        f"{'worse':>5} {'alarm':>5} {'s/run':>6}"
    )
    worse_total = 0
    for function in args.functions.split(","):
        for profile_id in [p for p in PROFILES[function] if not args.profiles or p in args.profiles.split(",")]:
            for helpful in (True, False):
                rng = random.Random(f"{function}-{profile_id}-{helpful}")
                counts: Counter[str] = Counter()
                walls = []
                for _ in range(seeds):
                    settings = machine(rng, function, helpful, (low, high))
                    if profile_id in real_time:
                        outcome, wall = run_real_time(function, profile_id, settings, args.port_base)
                        walls.append(wall)
                    else:
                        outcome = run_one(function, profile_id, settings)
                    if outcome.startswith("error"):
                        print(f"  {profile_id} {settings}: {outcome}")
                    counts[outcome] += 1
                worse_total += counts["worse"]
                kind = "could-help" if helpful else "no-help"
                per_run = f"{sum(walls) / len(walls):6.0f}" if walls else f"{'-':>6}"
                print(
                    f"{function:9} {profile_id:7} {kind:10} {'real' if walls else 'virtual':7} {seeds:8d} "
                    f"{counts['improved'] / seeds:8.0%} {counts['unchanged'] / seeds:9.0%} {counts['worse']:5d} "
                    f"{counts['alarm']:5d} {per_run}"
                )
    print(f"left worse: {worse_total} (must be 0); {time.monotonic() - t0:.0f} s wall, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
