"""The README's first command, run after run: `servotool run examples/commission.yaml --yes` (issue 33 item 1).

Copies the examples folder to a temporary one (a fresh clone: no backups, no report), gives it a fresh simulated
drive state, and runs the plan N times in a row there through the CLI, in real time, as a user would: the first run
is a fresh clone's, the rest are re-runs. Prints each run's exit code, time and any failed step, and the passes;
`--burner` runs one CPU-burning process (`python -c 'while 1: pass'`) beside it, `--line-baud N` sets the simulated
line (`sim config --line-baud`, 0 = as fast as the host) before the first run.

    python bench/example_plan.py [--runs 5] [--burner] [--line-baud N] [--tune 'rigidity: 13, travel: 3']

`--tune` replaces the options of the plan's `tune inertia` step (to compare choices).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--burner", action="store_true", help="one CPU-burning process beside the runs")
    parser.add_argument("--line-baud", type=int, default=None, help="the simulated line's baud (0: off)")
    parser.add_argument("--tune", default=None, help="options of the tune inertia step instead of the plan's")
    args = parser.parse_args()
    burner = subprocess.Popen([sys.executable, "-c", "while 1: pass"]) if args.burner else None
    try:
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp) / "examples"
            shutil.copytree(ROOT / "examples", folder)
            if args.tune is not None:
                plan = folder / "commission.yaml"
                lines = plan.read_text(encoding="utf-8").splitlines(keepends=True)
                at = next(i for i, line in enumerate(lines) if line.lstrip().startswith("- tune inertia:"))
                lines[at] = f"  - tune inertia: {{{args.tune}}}\n"
                plan.write_text("".join(lines), encoding="utf-8")
            env = {
                **os.environ,
                "SERVOTOOL_SIM_DIR": str(Path(tmp) / "sim"),
                "SERVOTOOL_BACKUP_DIR": str(Path(tmp) / "backups"),
                "SERVOTOOL_CONFIG": str(Path(tmp) / "none.yaml"),
                "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
            }
            servotool = [sys.executable, "-m", "servotool"]
            if args.line_baud is not None:
                for unit in ("1", "2"):
                    subprocess.run(
                        [*servotool, "sim", "config", "-P", "dsx7e", "-u", unit, "--line-baud", str(args.line_baud)],
                        env=env,
                        check=True,
                        stdout=subprocess.DEVNULL,
                    )
            passes = 0
            for i in range(args.runs):
                t0 = time.perf_counter()
                proc = subprocess.run(
                    [*servotool, "run", str(folder / "commission.yaml"), "--yes", "--json"],
                    env=env,
                    capture_output=True,
                    text=True,
                    cwd=tmp,
                )
                seconds = time.perf_counter() - t0
                passes += proc.returncode == 0
                failed = ""
                try:
                    steps = json.loads(proc.stdout)["steps"]
                    failed = "; ".join(f"unit {s['unit']} {s['name']}: {s['detail']}" for s in steps if not s["ok"])
                except (ValueError, KeyError, TypeError):
                    failed = proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else ""
                print(f"run {i + 1}: exit {proc.returncode} in {seconds:.1f} s" + (f"  {failed}" if failed else ""))
    finally:
        if burner is not None:
            burner.kill()
            burner.wait()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"{passes}/{args.runs} passed ({'one CPU burner beside' if args.burner else 'no burner'}"
        + (f", tune inertia {{{args.tune}}}" if args.tune else "")
        + (f", line {args.line_baud} baud" if args.line_baud is not None else "")
        + f"; "
        f"load average {load:.1f} on {os.cpu_count()} cores)"
    )


if __name__ == "__main__":
    main()
