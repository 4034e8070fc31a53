"""Start-up time of one-shot commands against importing the Modbus library they are built on.

Three commands, each a new process, against `python -c "import pymodbus.client"` in the same run, interleaved:

    --help                                   target <= 1.5x
    --port sim param get Pn004               target <= 1.5x (the embedded simulator: pymodbus serves it)
    -P sd25 --port PTY param get Po109       target <= 1.2x (a socat pty pair, `servotool sim serve -P sd25
                                             --line-baud 0` on the other end: start-up, not the wire time)

Prints the median of --runs runs of each (min, max), the ratio to the baseline, and the machine's load before and
after. Both sides run with their bytecode cached (PYTHONPYCACHEPREFIX in a temporary folder, even where
PYTHONDONTWRITEBYTECODE is set: an installed package has its .pyc files), after one warm-up run of each, so that
both find their files in the OS cache and servotool its compiled profile in its cache (a temporary one).

--callgrind counts each command's instructions under valgrind (one run each, independent of the load; slow).

    python bench/startup.py [--runs N] [--callgrind]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PY = [sys.executable]
BASELINE = ("import pymodbus.client", [*PY, "-c", "import pymodbus.client"], None)
HELP = ("--help", [*PY, "-m", "servotool", "--help"], 1.5)
SIM = ("--port sim param get Pn004", [*PY, "-m", "servotool", "--port", "sim", "param", "get", "Pn004"], 1.5)


def pty_command(port: str) -> tuple[str, list[str], float]:
    return ("-P sd25 --port PTY param get Po109", [*PY, "-m", "servotool", "-P", "sd25", "--port", port, "param",
                                                   "get", "Po109"], 1.2)  # fmt: skip


def seconds(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def instructions(cmd: list[str], env: dict[str, str], tmp: Path) -> int:
    """Instructions one run executes (valgrind's callgrind: the same on a busy and an idle machine)."""
    out = tmp / "callgrind.out"
    r = subprocess.run(
        ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", *cmd],
        env=env,
        cwd=ROOT,
        check=True,
        capture_output=True,
        text=True,
    )
    return int(re.findall(r"Collected : (\d+)", r.stderr)[-1])


def load() -> str:
    return "load average " + " ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"


class PtySim:
    """A socat pty pair with `servotool sim serve -P sd25` on one end; `port` is the other end."""

    def __init__(self, tmp: Path, env: dict[str, str]) -> None:
        self.port, served = str(tmp / "ttyA"), str(tmp / "ttyB")
        self.socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={self.port}", f"pty,raw,echo=0,link={served}"], stderr=subprocess.DEVNULL
        )
        deadline = time.monotonic() + 10
        while not (Path(self.port).exists() and Path(served).exists()) and time.monotonic() < deadline:
            time.sleep(0.02)
        serve = [*PY, "-m", "servotool", "sim", "serve", "-P", "sd25", "--port", served, "--line-baud", "0"]
        self.server = subprocess.Popen(serve, env=env, cwd=ROOT, stderr=subprocess.PIPE, text=True)
        assert self.server.stderr is not None
        for line in self.server.stderr:  # "serving on ..." once it answers
            if "serving on" in line:
                break

    def close(self) -> None:
        for p in (self.server, self.socat):
            p.terminate()
            p.wait(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9)
    parser.add_argument("--callgrind", action="store_true", help="count instructions instead (one run each)")
    args = parser.parse_args()
    print(load())
    with tempfile.TemporaryDirectory() as name:
        tmp = Path(name)
        env = {
            **{k: v for k, v in os.environ.items() if not k.startswith("SERVOTOOL_")},  # no user's port or profile
            "SERVOTOOL_SIM_DIR": str(tmp / "sim"),
            "SERVOTOOL_CONFIG": str(tmp / "none.yaml"),
            "SERVOTOOL_BACKUP_DIR": str(tmp / "backups"),
            "PYTHONPYCACHEPREFIX": str(tmp / "pyc"),
            "SERVOTOOL_CACHE_DIR": str(tmp / "cache"),
            "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
        }
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        pty = PtySim(tmp, env) if shutil.which("socat") else None
        try:
            commands = [BASELINE, HELP, SIM, *([pty_command(pty.port)] if pty else [])]
            for _, cmd, _ in commands:  # warm-up: OS cache, bytecode, compiled profiles
                seconds(cmd, env)
            if args.callgrind:
                counts = {label: instructions(cmd, env, tmp) for label, cmd, _ in commands}
                base = counts[BASELINE[0]]
                for label, _, target in commands:
                    ratio = f"  {counts[label] / base:.2f}x" + (f" (target <= {target}x)" if target else "")
                    print(f"{label:38} {counts[label] / 1e6:7.0f}M instructions{ratio if target else ''}")
                return
            times: dict[str, list[float]] = {label: [] for label, _, _ in commands}
            for _ in range(args.runs):
                for label, cmd, _ in commands:
                    times[label].append(seconds(cmd, env))
        finally:
            if pty:
                pty.close()
    base = statistics.median(times[BASELINE[0]])
    for label, _, target in commands:
        t = times[label]
        line = f"{label:38} median {statistics.median(t) * 1000:4.0f} ms of {len(t)} (min {min(t) * 1000:.0f}, "
        line += f"max {max(t) * 1000:.0f})"
        if target:
            line += f"  {statistics.median(t) / base:.2f}x (target <= {target}x)"
        print(line)
    if not pty:
        print("(no socat: the pty command was not run)")
    print(load())


if __name__ == "__main__":
    main()
