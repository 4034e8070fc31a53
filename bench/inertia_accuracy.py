"""Accuracy of `tune inertia` (host method) on the simulated drive over a grid of machines and line speeds.

The wizard's own code runs against the simulated drive's registers and firmware on virtual time; each request
costs the RS485 wire time of its frames at the given baud, so 19200 baud samples as slowly as a real bus.
Prints: true ratio, estimate, error %, travel used, time used, samples/s. Target: median |error| <= 2 %,
worst <= 5 %, travel <= 2 rev, time <= 10 s.

Run: python bench/inertia_accuracy.py [--quick]
"""

from __future__ import annotations

import argparse
import itertools
import os
import statistics
import tempfile

from servotool.drive import Drive
from servotool.profile import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.plant import VirtualClock
from servotool.sim.registers import SimRefusal
from servotool.sim.server import wire_time
from servotool.tuning import wizard


class WireLink:
    """A Link straight into a SimulatedDrive that advances virtual time by each request's wire time."""

    def __init__(self, sim, clock: VirtualClock, baud: int) -> None:
        self.sim, self.clock, self.baud = sim, clock, baud

    def read(self, unit: int, address: int, count: int) -> list[int]:
        self.clock.advance(wire_time(3, count, self.baud) + 0.0005)
        try:
            return self.sim.read(address, count)
        except SimRefusal as exc:
            raise RuntimeError(exc) from None

    def write(self, unit: int, address: int, values: list[int], *, multiple: bool = True) -> None:
        self.clock.advance(wire_time(16 if multiple and len(values) > 1 else 6, len(values), self.baud) + 0.0005)
        self.sim.write(address, values)

    def close(self) -> None:
        pass


class VirtualTiming:
    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock

    def now(self) -> float:
        return self.clock.now()

    def sleep(self, seconds: float) -> None:
        self.clock.advance(max(0.0, seconds))


def identify(ratio: float, friction: float, gravity: float, noise: float, baud: int, seed: int):
    profile = load_profile("dsx7e")
    clock = VirtualClock(1000.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(load_ratio=ratio, friction=friction, load_torque=gravity, noise=noise, seed=seed)
    sim.firmware.reconfigure()
    drive = Drive(WireLink(sim, clock, baud), profile, 1)
    plan = wizard.plan_motion(profile, max_speed=None, accel_time_ms=200, travel_rev=2.0, direction="both",
                              repeats=3)
    return wizard.Identifier(drive, VirtualTiming(clock)).run_host(plan)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="a smaller grid")
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    ratios = [0.0, 3.0, 20.0, 50.0] if args.quick else [0.0, 1.0, 3.0, 10.0, 20.0, 35.0, 50.0]
    frictions = [0.02] if args.quick else [0.01, 0.05]
    gravities = [0.0, 0.1]
    noises = [0.002] if args.quick else [0.001, 0.004]
    bauds = [19200, 115200]
    print(f"{'baud':>6} {'true':>6} {'fric':>5} {'grav':>5} {'noise':>6} {'est':>8} {'err%':>7} {'travel':>7} "
          f"{'time_s':>7} {'samp/s':>7}")
    errors, worst_travel, worst_time, failures = [], 0.0, 0.0, 0
    for n, (baud, ratio, fr, gr, nz) in enumerate(itertools.product(bauds, ratios, frictions, gravities, noises)):
        try:
            r = identify(ratio, fr, gr, nz, baud, seed=n + 1)
        except Exception as exc:
            failures += 1
            print(f"{baud:>6} {ratio:>6.1f} {fr:>5.2f} {gr:>5.2f} {nz:>6.3f}  REFUSED: {exc}")
            continue
        # error relative to the total inertia the loop sees (ratio 0 has no relative error of its own)
        err = (r.new_ratio - ratio) / (1.0 + ratio) * 100
        errors.append(abs(err))
        worst_travel = max(worst_travel, r.travel_used_rev)
        worst_time = max(worst_time, r.time_used_s)
        print(f"{baud:>6} {ratio:>6.1f} {fr:>5.2f} {gr:>5.2f} {nz:>6.3f} {r.new_ratio:>8.3f} {err:>7.2f} "
              f"{r.travel_used_rev:>7.2f} {r.time_used_s:>7.2f} {r.samples_per_s:>7.1f}")
    if errors:
        print(f"\nruns {len(errors) + failures}, refused {failures}; |error| of J_total: median "
              f"{statistics.median(errors):.2f} %, worst {max(errors):.2f} %; worst travel {worst_travel:.2f} rev, "
              f"worst time {worst_time:.1f} s (targets: median <= 2 %, worst <= 5 %, <= 2 rev, <= 10 s)")


if __name__ == "__main__":
    main()
