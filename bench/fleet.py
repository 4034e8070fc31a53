"""Many buses at once: `servotool fleet backup` over 4 simulated buses of 6 drives each, against the slowest bus alone.

Run: python bench/fleet.py [--buses 4] [--units 6] [--profile sd25] [--line-baud 19200] [--action backup|drift]
     [--runs 1] [--port-base N]
Starts one `sim serve` per bus (its own drives, its line emulated at --line-baud: each answer after its wire time),
runs the CLI on an inventory of each bus alone, then on all of them, and prints each wall time, the slowest single
bus, the time of all at once and their ratio (target <= 1.2), with the load before and after. Times are the CLI's
own (`time` in its JSON: from the first port opened to the last table row) and the process's, start-up included.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

TARGET = 1.2


def serve(folder: Path, profile: str, units: int, line_baud: str, port: int) -> tuple[subprocess.Popen[str], str]:
    args = [sys.executable, "-m", "servotool", "sim", "serve", "--port", f"tcp://127.0.0.1:{port}", "-P", profile]
    args += ["--line-baud", line_baud]
    for u in range(1, units + 1):
        args += ["--unit", str(u)]
    env = {**os.environ, "SERVOTOOL_SIM_DIR": str(folder)}
    env.pop("SERVOTOOL_SIM_LINE_BAUD", None)
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env)
    assert proc.stderr is not None
    banner = proc.stderr.readline()
    found = re.search(r"serving on (tcp://\S+)", banner)
    if not found:
        proc.terminate()
        raise SystemExit(f"sim serve did not start: {banner.strip()}")
    return proc, found.group(1)


def run(work: Path, name: str, buses: list[dict], action: str, env: dict[str, str]) -> tuple[float, float, dict]:
    """(the CLI's own time, the process's wall time, its JSON) for one inventory."""
    inv = work / f"{name}.yaml"
    inv.write_text(yaml.safe_dump({"servotool_fleet": 1, "defaults": {"boost": False}, "buses": buses}))
    extra = ["-o", str(work / f"snaps-{name}")] if action == "backup" else []
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-m", "servotool", "fleet", action, str(inv), *extra, "--json", "-q"],
        capture_output=True,
        text=True,
        env=env,
        timeout=1800,
    )
    wall = time.monotonic() - t0
    data = json.loads(r.stdout)
    if r.returncode not in (0, 1):
        raise SystemExit(f"{name}: exit {r.returncode}: {r.stderr.strip()[-400:]}")
    return float(data["time"]["value"]), wall, data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--buses", type=int, default=4)
    ap.add_argument("--units", type=int, default=6)
    ap.add_argument("--profile", default="sd25")
    ap.add_argument("--line-baud", default="19200", help="the simulated line's speed (factory: the profile's)")
    ap.add_argument("--action", choices=("backup", "drift"), default="backup")
    ap.add_argument("--runs", type=int, default=1, help="repeat the all-at-once run (the best and worst shown)")
    ap.add_argument("--port-base", type=int, default=0, help="serve bus i on TCP port BASE+i (default: any free)")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="servotool-bench-fleet-"))
    env = {**os.environ, "SERVOTOOL_BACKUP_DIR": str(work / "backups"), "SERVOTOOL_CONFIG": str(work / "none.yaml")}
    env.pop("SERVOTOOL_SIM_LINE_BAUD", None)
    golden = work / "golden.yaml"
    golden.write_text(yaml.safe_dump({"servotool_settings": 1, "parameters": {"Po101": 40.0}}))
    procs = []
    load_before = os.getloadavg()
    try:
        buses = []
        for i in range(args.buses):
            proc, port = serve(
                work / f"sim{i}", args.profile, args.units, args.line_baud, args.port_base + i if args.port_base else 0
            )
            procs.append(proc)
            bus = {"machine": f"machine-{i + 1}", "port": port, "profile": args.profile}
            bus["units"] = list(range(1, args.units + 1))
            if args.action == "drift":
                bus["golden"] = str(golden)
            buses.append(bus)
        print(
            f"fleet {args.action}: {args.buses} buses x {args.units} {args.profile} drives, line emulated at "
            f"{args.line_baud} baud; load before {load_before[0]:.2f} ({os.cpu_count()} cores)"
        )
        singles = []
        for bus in buses:
            own, wall, _data = run(work, bus["machine"], [bus], args.action, env)
            singles.append(own)
            print(f"  {bus['machine']} alone: {own:6.2f} s (process {wall:6.2f} s)")
        together = []
        for k in range(args.runs):
            own, wall, data = run(work, f"all-{k}", buses, args.action, env)
            together.append(own)
            per_bus = ", ".join(f"{b['time']['value']:.2f}" for b in data["buses"])
            print(f"  all {args.buses} at once: {own:6.2f} s (process {wall:6.2f} s; each bus {per_bus} s)")
            print(f"    {data['summary']}")
        slowest = max(singles)
        worst = max(together)
        ratio = worst / slowest
        load_after = os.getloadavg()
        verdict = "meets" if ratio <= TARGET else "MISSES"
        print(
            f"slowest bus alone {slowest:.2f} s, all at once {worst:.2f} s (best {min(together):.2f} s): ratio "
            f"{ratio:.2f} ({verdict} the target <= {TARGET}); sequentially they would take {sum(singles):.2f} s; "
            f"load after {load_after[0]:.2f}"
        )
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            proc.wait(timeout=30)
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
