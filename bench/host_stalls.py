"""Identification on a host that stalls (a loaded laptop, a scheduler tick, a USB adapter's latency timer): does the
stop guard keep the axis inside its travel, and does a refusal name the stall instead of the mechanics?

Each request, with a given probability, waits a uniform min..max before it is sent (sim.virtual.HostStalls, seeded),
on virtual time, through tune_inertia as the CLI runs it (a dry run; where it names the travel the line needs, once
more with it, as a user does). Every outcome is counted: identified, refused (too uncertain for the shorter moves the
guard allows: honest), or stopped at the travel limit (the guard failed to foresee the stall: the axis went past
--travel). Targets: no travel trips where the stall has been seen before (a stall longer than any before can still
surprise the guard, which then stops the motion), and no refusal or note on these rigid loads that blames a
resonance, backlash, the loop, the sign convention or the zero-speed band (bench/realtime.py's WRONG_CAUSES): a stall
is named as one. The last rows are issue 31's: gaps of 0.1-0.34 s.

Run: python bench/host_stalls.py [--machines 20] [--long]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from inertia_accuracy import identify_once
from realtime import WRONG_CAUSES

from servotool.errors import ServoError
from servotool.sim.virtual import HostStalls
from servotool.tuning.errors import TravelExceeded, TravelNeeded
from servotool.tuning.identify import IdentificationRefused

ROWS = [("dsx7e", 115200), ("dsx7e", 19200), ("is620p", 57600), ("sdc", 19200), ("sd25", 19200)]
# (share of requests, shortest, longest stall in s)
STALLS = [(0.0, 0.01, 0.05), (0.02, 0.01, 0.05), (0.05, 0.01, 0.03), (0.005, 0.01, 0.1)]
LONG_STALLS = [(0.005, 0.1, 0.34), (0.02, 0.1, 0.34)]  # issue 31: sampling gaps of 0.1-0.34 s in real time
LOADS = [0.0, 1.0, 4.0, 10.0, 37.0]


def outcome(profile_id: str, baud: int, ratio: float, seed: int, stalls: HostStalls) -> tuple[str, str]:
    """(kind, the words a wrong cause was named in, or "")."""
    try:
        run = identify_once(ratio, 0.02, 0.0, 0.002, baud, seed, profile_id=profile_id, stalls=stalls)
    except TravelExceeded as exc:
        return "travel trip", _wrong(str(exc))
    except IdentificationRefused as exc:
        est = exc.result.estimate
        return "refused", _wrong(" ".join([str(exc), *(est.notes if est else ())]))
    except TravelNeeded as exc:
        return "travel named", _wrong(str(exc))
    except ServoError as exc:
        return f"failed: {exc}"[:60], _wrong(str(exc))
    est = run.identified.estimate
    return "identified", _wrong(" ".join(est.notes if est else ()))


def _wrong(text: str) -> str:
    found = WRONG_CAUSES.search(text)
    return text if found else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--machines", type=int, default=20, help="machines per cell (loads x seeds)")
    ap.add_argument("--long", action="store_true", help="only issue 31's long stalls (0.1-0.34 s)")
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    machines = [(LOADS[n % len(LOADS)], n // len(LOADS) + 1) for n in range(args.machines)]
    print(
        f"{'profile':>7} {'baud':>6} {'stall rate':>10} {'ms':>7}  identified  refused  named  travel trips  "
        "wrong cause"
    )
    wrong: list[str] = []
    for pid, baud in ROWS:
        for rate, lo, hi in LONG_STALLS if args.long else STALLS + LONG_STALLS:
            counts: Counter[str] = Counter()
            blamed = 0
            for ratio, seed in machines:
                kind, words = outcome(pid, baud, ratio, seed, HostStalls(rate, hi, seed, lo))
                counts[kind] += 1
                if words:
                    blamed += 1
                    wrong.append(f"{pid} {baud} {rate:.1%} {lo * 1000:.0f}-{hi * 1000:.0f} ms, load {ratio}: {words}")
            print(
                f"{pid:>7} {baud:>6} {rate:>10.1%} {f'{lo * 1000:.0f}-{hi * 1000:.0f}':>7}  {counts['identified']:>10} "
                f"{counts['refused']:>8} {counts['travel named']:>6} {counts['travel trip']:>13} {blamed:>12}",
                flush=True,
            )
            for other in set(counts) - {"identified", "refused", "travel trip", "travel named"}:
                print(f"{'':>34}{counts[other]} x {other}")
    print(f"\nwrong causes named: {len(wrong)}")
    for line in wrong:
        print("  " + line[:300])


if __name__ == "__main__":
    main()
