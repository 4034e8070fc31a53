"""Sampling rate of `servotool trace` per profile and baud rate, on the simulated drive over virtual time.

Each request costs the RS485 wire time of its frames at the given baud plus a turnaround (sim/virtual.py), so the
figures are what a clean line allows: samples per second for the key motion entries (speed, command, torque,
position) read in as few requests as each profile permits, and the requests one sample takes. Jitter on a real line
comes from the host and the drive's reply time, which virtual time does not model: measure it with
`servotool trace ... --samples 1000` on the line itself (the CSV header and the summary report it).

Run: python bench/trace_rate.py
"""

from __future__ import annotations

import os
import tempfile

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.ops.trace import Tracer, Window, motion_entries
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink

PROFILES = ("dsx7e", "sd25", "is620p", "sdc")
BAUDS = (9600, 19200, 38400, 57600, 115200)


def rate(profile_id: str, baud: int, speed_only: bool) -> tuple[float, int]:
    profile = load_profile(profile_id)
    clock = VirtualClock(0.0)
    sim = build_drive(profile, profile.default_unit, clock, persist=False)
    drive = Drive(VirtualLink([sim], clock, baud), profile, profile.default_unit)
    entries = motion_entries(profile)[:1] if speed_only else motion_entries(profile)
    tracer = Tracer(drive, entries, None, Window(samples=500), clock=clock)
    (cap,) = list(tracer.run())
    return cap.timing.rate_hz or 0.0, tracer.sampler.requests_per_sample


def main() -> None:
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp(prefix="trace-bench-"))
    print(f"{'profile':8} {'entries':32} {'req/sample':>10} " + " ".join(f"{b:>8}" for b in BAUDS))
    for pid in PROFILES:
        for speed_only in (True, False):
            entries = motion_entries(load_profile(pid))
            names = ",".join(e.code for e in (entries[:1] if speed_only else entries))
            figures = [rate(pid, b, speed_only) for b in BAUDS]
            print(f"{pid:8} {names:32} {figures[0][1]:>10} " + " ".join(f"{r:>7.0f}/s" for r, _ in figures))


if __name__ == "__main__":
    main()
