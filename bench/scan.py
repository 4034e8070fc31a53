"""How long `servotool scan` takes for 247 unit ids at one line setting, against the time its timeout alone allows.

Run: python bench/scan.py [--timeout S] [--pty]
Starts `servotool sim serve` (SD25 drives on units 5 and 200) on a loopback tcp:// port (and, with --pty and socat,
on a serial pty at 115200 8N1), scans ids 1..247 once, and prints the time, 247 x timeout, their ratio (target
<= 1.5) and what was found.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from servotool.model.profile import LineSettings
from servotool.ops.identity import shipped_profiles
from servotool.ops.scan import SCAN_TIMEOUT, scan

UNITS = list(range(1, 248))


def serve(port: str, *extra: str) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "sim",
            "serve",
            "-P",
            "sd25",
            "-u",
            "5",
            "-u",
            "200",
            "--port",
            port,
            *extra,
        ],
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()
    m = re.search(r"serving on (\S+)", line)
    if not m:
        proc.terminate()
        raise SystemExit(f"sim serve did not start: {line.strip()}")
    return proc, m[1]


def measure(label: str, port: str, timeout: float, line: LineSettings) -> None:
    result = scan(port, UNITS, [line], shipped_profiles(), timeout=timeout)
    budget = len(UNITS) * timeout
    found = ", ".join(f"unit {f.unit} = {f.best.profile.id if f.best else '?'}" for f in result.found)
    print(
        f"{label}: {len(UNITS)} ids in {result.seconds:6.2f} s; timeout alone {budget:6.2f} s; "
        f"ratio {result.seconds / budget:4.2f} (target <= 1.50); found {found or 'nothing'}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--timeout", type=float, default=SCAN_TIMEOUT)
    ap.add_argument("--pty", action="store_true", help="also over a socat pty (serial RTU at 115200 8N1)")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    os.environ.setdefault("SERVOTOOL_SIM_DIR", str(tmp / "sim"))
    server, port = serve("tcp://127.0.0.1:0")
    try:
        measure("sim serve over loopback tcp", port, args.timeout, LineSettings())
    finally:
        server.terminate()
    if args.pty and shutil.which("socat"):
        a, b = tmp / "a", tmp / "b"
        socat = subprocess.Popen(
            ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"], stderr=subprocess.DEVNULL
        )
        while not (a.exists() and b.exists()):
            time.sleep(0.05)
        server, _ = serve(str(a), "--baud", "115200")
        try:
            measure("sim serve over a socat pty (115200 8N1)", str(b), args.timeout, LineSettings(115200, "N", 1, 8))
        finally:
            server.terminate()
            socat.terminate()


if __name__ == "__main__":
    main()
