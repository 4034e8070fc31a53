"""Where the line's time goes during an identification (issue 16 item 1: the sample rate against the line's).

Runs `tune inertia` (a dry run, as bench/inertia_accuracy.py --profiles) on the simulated drive on virtual time and
records every request with its wire time and the servotool function that made it, then adds them up by kind over the
identification's sampling window (first to last sample: what Sampler.rate() divides by):

  samples   speed and torque reads (Sampler._read)
  position  position reads of their own (Sampler.sample, when due)
  beat      keep-alive writes (KeepAlive.beat: the keep-alive entry)
  re-arm    a segment started again by a beat (IS620P: a drive without a keep-alive entry)
  command   the moves' own commands (start, stop, a fresh segment), speed and ramp writes and their checks
  hold      StableHold's reads and writes (after the pilot)
  alarm     the alarm check after each move
  other     anything else
  host      time on no request (host computing or sleeping on virtual time: 0 unless it sleeps)

share: samples/s over what the line carries for speed and torque back to back (as inertia_accuracy's column). It
counts from the identification's first sample (the pilot's, after the rest check and the motion's set-up) to its last
(before the settings are put back): the pilot counts (the fit uses its moves), as does everything between moves
(the rest there is sampled too). Nothing in that window is outside the identification: the hold's writes after the
pilot, the one part that could be argued out, are about 0.5 % of it.

Run: python bench/line_budget.py [--profile is620p] [--baud 57600] [--machines 6]
share: the median over the machines (as inertia_accuracy's column).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from collections import Counter
from dataclasses import dataclass, field

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from inertia_accuracy import draws, line_rate

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import TURNAROUND_S, VirtualLink, make_motion_setup, wire_time
from servotool.tuning.tune import TuneRequest, tune_inertia

# The first function on the stack (innermost first) that names the kind of a request.
KINDS = [
    ("_read", "samples"),
    ("Sampler.sample", "position"),
    ("_resend_command", "re-arm"),
    ("KeepAlive.beat", "beat"),
    ("StableHold.", "hold"),
    ("active_alarm", "alarm"),
    ("Mover.start", "command"),
    ("Jogger.set_speed", "command"),
    ("Jogger.set_ramp", "command"),
    ("Jogger.command", "command"),
]


def kind_of() -> str:
    frame = sys._getframe(2)
    while frame is not None:
        name = frame.f_code.co_qualname
        for key, kind in KINDS:
            if (name.startswith(key) if key.endswith(".") else name.endswith(key)) and (
                key != "_read" or "Sampler" in name
            ):
                return kind
        frame = frame.f_back
    return "other"


@dataclass
class Request:
    start: float
    seconds: float
    kind: str


@dataclass
class RecordingLink(VirtualLink):
    """A VirtualLink that records each request's start, wire time and kind."""

    log: list[Request] = field(default_factory=list)

    def __init__(self, drives: list, clock: VirtualClock, baud: int) -> None:  # type: ignore[type-arg]
        super().__init__(drives, clock, baud)
        self.log = []

    def read(self, unit: int, address: int, count: int, *, spare: tuple[int, int] = (0, 0)) -> list[int]:
        self.log.append(Request(self.clock.now(), wire_time(3, count, self.baud) + TURNAROUND_S, kind_of()))
        return super().read(unit, address, count)

    def write(
        self, unit: int, address: int, values: list[int], *, multiple: bool = True, idempotent: bool = True
    ) -> None:
        fc = 16 if multiple or len(values) > 1 else 6
        self.log.append(Request(self.clock.now(), wire_time(fc, len(values), self.baud) + TURNAROUND_S, kind_of()))
        super().write(unit, address, values, multiple=multiple, idempotent=idempotent)


def budget(
    profile_id: str,
    baud: int,
    ratio: float,
    friction: float,
    gravity: float = 0.0,
    noise: float = 0.002,
    viscous: float = 0.0005,
    seed: int = 1,
) -> dict[str, object]:
    """One identification's requests by kind over its sampling window: counts, seconds, and the share."""
    profile = load_profile(profile_id)
    clock = VirtualClock(1000.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(
        load_ratio=ratio, friction=friction, viscous=viscous, load_torque=gravity, noise=noise, seed=seed, brake=1
    )
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    link = RecordingLink([sim], clock, baud)
    drive = Drive(link, profile, 1)
    drive.dead_man_waived = True
    try:
        result = tune_inertia(drive, TuneRequest(travel_rev=2.0, dry_run=True), clock=clock)
        ident, outcome = result.identified, "ok"
        trace = ident.trace
    except ServoError as exc:
        ident, outcome = None, str(exc)[:60]
        trace = getattr(getattr(exc, "result", None), "trace", None)
    samples = [r for r in link.log if r.kind == "samples"]
    if not samples:
        return {"outcome": outcome}
    first, last = samples[0].start, samples[-1].start + samples[-1].seconds
    window = [r for r in link.log if first <= r.start < last]
    counts, secs = Counter(r.kind for r in window), Counter()
    for r in window:
        secs[r.kind] += r.seconds
    secs["host"] = (last - first) - sum(r.seconds for r in window)
    n = len(trace.t) if trace is not None else 0
    rate = ident.samples_per_s if ident is not None else (n - 1) / (trace.t[-1] - trace.t[0]) if n > 1 else 0.0
    return {
        "outcome": outcome,
        "counts": counts,
        "seconds": secs,
        "window_s": last - first,
        "rate": rate,
        "share": rate / line_rate(profile_id, baud),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--profile", action="append")
    ap.add_argument("--baud", type=int, action="append")
    ap.add_argument("--machines", type=int, default=6, help="the first N of inertia_accuracy's quick draws")
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    rows = [(p, b) for p in (args.profile or ["is620p", "dsx7e"]) for b in (args.baud or [57600, 19200])]
    kinds = ["samples", "position", "beat", "re-arm", "command", "hold", "alarm", "other", "host"]
    print(f"requests (count, % of the sampling window) summed over {args.machines} machines")
    print(f"{'profile':>7} {'baud':>6} {'share':>5} {'window':>6}  " + "  ".join(f"{k:>13}" for k in kinds))
    for pid, baud in rows:
        counts: Counter[str] = Counter()
        secs: Counter[str] = Counter()
        window, shares = 0.0, []
        for n, (ratio, fr, visc, gr, nz) in enumerate(draws(True)[: args.machines]):
            b = budget(pid, baud, ratio, fr, gr, nz, viscous=visc, seed=n + 1)
            if "counts" not in b:
                continue
            counts.update(b["counts"])
            secs.update(b["seconds"])
            window += b["window_s"]
            shares.append(b["share"])
        cells = [f"{counts.get(k, 0):>5} {100 * secs.get(k, 0.0) / window:>5.1f}%" for k in kinds]
        print(
            f"{pid:>7} {baud:>6} {statistics.median(shares):>5.2f} {window:>6.2f}  "
            + "  ".join(f"{c:>13}" for c in cells)
        )


if __name__ == "__main__":
    main()
