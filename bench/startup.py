"""Start-up time of a one-shot command against importing the Modbus library it is built on (issue 17 item 2).

Runs `servotool --port sim param get Pn004` (a new process each time, on the embedded simulator) and
`python -c "import pymodbus.client"` alternately, 7 times each by default, and prints the medians and their ratio
(target: at most 2x). Both run with their bytecode cached (PYTHONPYCACHEPREFIX in a temporary folder, even where
PYTHONDONTWRITEBYTECODE is set: an installed package has its .pyc files), after one warm-up run of each, so that both
find their files in the OS cache and servotool its compiled profile and dataclass methods in the cache (a temporary
one: the user's is shared with every other copy of servotool, whose different model code replaces the entry).

    python bench/startup.py [--runs N]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SERVOTOOL = [sys.executable, "-m", "servotool", "--port", "sim", "param", "get", "Pn004"]
BASELINE = [sys.executable, "-c", "import pymodbus.client"]


def seconds(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        env = {
            **os.environ,
            "SERVOTOOL_SIM_DIR": str(Path(tmp) / "sim"),
            "SERVOTOOL_CONFIG": str(Path(tmp) / "none.yaml"),
            "PYTHONPYCACHEPREFIX": str(Path(tmp) / "pyc"),
            "SERVOTOOL_CACHE_DIR": str(Path(tmp) / "cache"),
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        }
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        seconds(SERVOTOOL, env)
        seconds(BASELINE, env)
        ours, base = [], []
        for _ in range(args.runs):
            ours.append(seconds(SERVOTOOL, env))
            base.append(seconds(BASELINE, env))
    a, b = statistics.median(ours), statistics.median(base)
    print(
        f"servotool --port sim param get Pn004: median {a * 1000:.0f} ms of {args.runs} "
        f"(min {min(ours) * 1000:.0f}, max {max(ours) * 1000:.0f})"
    )
    print(
        f"python -c 'import pymodbus.client':  median {b * 1000:.0f} ms of {args.runs} "
        f"(min {min(base) * 1000:.0f}, max {max(base) * 1000:.0f})"
    )
    print(f"ratio {a / b:.2f}x (target <= 2x)")


if __name__ == "__main__":
    main()
