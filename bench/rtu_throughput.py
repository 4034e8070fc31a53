"""Requests per second through servotool's RTU path: embedded simulator (RTU over loopback TCP) and a socat pty.

Run: python bench/rtu_throughput.py [--requests N]
Prints one line per transport with requests/s and the mean round-trip time.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from servotool.connection import ConnectOptions, resolve
from servotool.session import open_drives


def measure(port: str, n: int, profile: str = "dsx7e", baud: int | None = None) -> tuple[float, float]:
    resolved = resolve(ConnectOptions(port=port, profile=profile, baud=baud, timeout=1.0, retries=0))
    with open_drives(resolved, notice=lambda _m: None) as (drive,):
        entry = drive.profile.entry("Pn004")
        drive.read_entries([entry])
        t0 = time.perf_counter()
        for _ in range(n):
            drive.read_entries([entry])
        elapsed = time.perf_counter() - t0
    return n / elapsed, elapsed / n * 1000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--requests", type=int, default=1000)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    os.environ.setdefault("SERVOTOOL_SIM_DIR", str(tmp / "sim"))
    rate, rtt = measure("sim", args.requests)
    print(f"embedded sim (RTU over loopback TCP): {rate:8.0f} requests/s  {rtt:6.3f} ms/request")
    if shutil.which("socat"):
        a, b = tmp / "a", tmp / "b"
        socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"], stderr=subprocess.DEVNULL
        )
        while not (a.exists() and b.exists()):
            time.sleep(0.05)
        server = subprocess.Popen(
            [sys.executable, "-m", "servotool", "sim", "serve", "--port", str(a), "--baud", "115200"],
            stderr=subprocess.PIPE,
            text=True,
        )
        server.stderr.readline()
        try:
            rate, rtt = measure(str(b), args.requests // 2, baud=115200)
            print(f"sim serve over a socat pty (serial RTU): {rate:8.0f} requests/s  {rtt:6.3f} ms/request")
        finally:
            server.terminate()
            socat.terminate()


if __name__ == "__main__":
    main()
