"""`tune inertia` on loads outside the estimator's rigid model (issue 16 item 4), on the simulated drive.

Same route as bench/inertia_accuracy.py (tune_inertia, dry run, virtual time, RS485 wire time at the given baud):
two-mass loads (a compliant coupling) at a few resonances, backlash, an arm's gravity varying with position
through a gear, and cogging. Each row is accepted (as is), flagged (accepted with a warning in its notes) or
refused (with its reason), with the error of J_total and the stated 3 sigma (% of J_total).

Target: no accepted (or flagged) result off by more than its stated 3 sigma.

Run: python bench/off_model.py [--quick] [--baud 19200] [--profile is620p --baud 57600] [--seeds N]
--seeds N: each machine N times with its own noise (one seed hid a backlash load accepted outside its
3 sigma in 7 of 14 runs).
     python bench/off_model.py --realtime [--quick] [--rows sdc:9600,...] [--seeds N] [--burner] [-v]
--realtime: the same loads through the CLI in real time against `sim serve` in its own process, at each profile's
factory line (bench/realtime.py: a travel servotool names is followed once, as a user would); per row the accepted,
flagged and refused, the truth within 3 sigma and twice it, and the arms' mean signed error (issue 31 item 5:
within 1 %).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from inertia_accuracy import REALTIME_ROWS, add_realtime_options, bench_travel, fit_brake

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import ServoError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import TuneRequest, tune_inertia

# (label, sim settings); every machine has a load ratio, Coulomb friction and noise as set in rows()
LOADS_QUICK: list[tuple[str, dict[str, float]]] = [
    ("two-mass 10 Hz", {"resonance_hz": 10.0, "resonance_damping": 0.05}),
    ("two-mass 20 Hz", {"resonance_hz": 20.0, "resonance_damping": 0.05}),
    ("two-mass 50 Hz", {"resonance_hz": 50.0, "resonance_damping": 0.05}),
    ("backlash 0.05 rad", {"backlash_rad": 0.05}),
    ("backlash 0.2 rad", {"backlash_rad": 0.2}),
    ("arm 10 % gear 10", {"arm_gravity": 0.1, "gear": 10.0}),
    ("arm 40 % gear 10", {"arm_gravity": 0.4, "gear": 10.0, "arm_angle": 30.0}),
    ("cogging 1 %", {"cogging": 0.01, "cogging_periods": 6}),
    ("cogging 5 %", {"cogging": 0.05, "cogging_periods": 6}),
]
LOADS_MORE: list[tuple[str, dict[str, float]]] = [
    ("two-mass 20 Hz damped", {"resonance_hz": 20.0, "resonance_damping": 0.2}),
    ("two-mass 100 Hz", {"resonance_hz": 100.0, "resonance_damping": 0.05}),
    ("backlash 0.1 rad", {"backlash_rad": 0.1}),
    ("backlash 0.1 + 30 Hz", {"backlash_rad": 0.1, "resonance_hz": 30.0}),
    ("arm 20 % gear 5", {"arm_gravity": 0.2, "gear": 5.0, "arm_angle": 60.0}),
    ("arm 40 % gear 3", {"arm_gravity": 0.4, "gear": 3.0, "arm_angle": 90.0}),
    ("cogging 3 % x 12", {"cogging": 0.03, "cogging_periods": 12}),
]


# A heavy load behind a stiff coupling, with noisier readings (label, sim settings, ratio, noise): SDC at 9600 baud
# (24 samples/s) accepted the 40 Hz one 8-10 % high with a stated 3 sigma of 3.2 %, since windows at torque steps,
# where the load does not follow the motor, read J 10-30 % high (the full run only; a few s each)
HEAVY: list[tuple[str, dict[str, float], float, float]] = [
    ("two-mass 40 Hz n0.5%", {"resonance_hz": 40.0, "resonance_damping": 0.05}, 37.0, 0.005),
    ("two-mass 60 Hz n0.5%", {"resonance_hz": 60.0, "resonance_damping": 0.05}, 37.0, 0.005),
]


def identify(
    ratio: float, machine: dict[str, float], baud: int, seed: int, profile_id: str = "dsx7e", noise: float = 0.002
):
    """(outcome, estimate or None, reason) of `tune inertia --dry-run` on one off-model machine (noise: the
    readings', relative)."""
    profile = load_profile(profile_id)
    clock = VirtualClock(1000.0)
    sim = build_drive(profile, 1, clock, persist=False)
    sim.settings.update(load_ratio=ratio, friction=0.02, noise=noise, seed=seed, **machine)
    sim.firmware.reconfigure()
    make_motion_setup(sim)
    fit_brake(sim.firmware.plant)
    drive = Drive(VirtualLink([sim], clock, baud), profile, 1)
    drive.dead_man_waived = True  # as --no-dead-man: SD25 and SDC have no dead-man route (the others keep theirs)
    try:
        r = tune_inertia(drive, TuneRequest(travel_rev=bench_travel(profile_id), dry_run=True), clock=clock)
    except IdentificationRefused as exc:
        return "refused", exc.result.estimate, str(exc).removeprefix("identification refused: ")
    except ServoError as exc:
        return "failed", None, str(exc)
    est = r.identified.estimate
    flagged = est is not None and any(n.startswith("off-model:") for n in est.notes)
    return ("flagged" if flagged else "accepted"), est, "; ".join(n for n in est.notes if n.startswith("off-model:"))


def outcome_of(
    ratio: float, machine: dict[str, float], baud: int, seed: int, profile_id: str, noise: float = 0.002
) -> tuple[str, float, float, str]:
    """(outcome, error % of J_total, stated 3 sigma %, reason or flags) of one run."""
    outcome, est, why = identify(ratio, machine, baud, seed=seed, profile_id=profile_id, noise=noise)
    err = sig3 = float("nan")
    if est is not None and est.j_total_kgm2 == est.j_total_kgm2:
        err = (est.load_ratio - ratio) / (1.0 + ratio) * 100
        sig3 = 3 * est.ratio_std / (1.0 + est.load_ratio) * 100
    return outcome, err, sig3, why


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="fewer loads and ratios")
    ap.add_argument("--baud", type=int, action="append", help="line speed (repeatable; default 19200 and 115200)")
    ap.add_argument(
        "--profile",
        default="dsx7e",
        help="the simulated drive's profile (default dsx7e; is620p at 57600 reads torque in whole percent)",
    )
    ap.add_argument(
        "--seeds",
        type=int,
        default=1,
        help="runs of each machine, each with its own noise (default 1: "
        "one row per run; more: one row per machine with its counts and worst error against 3 sigma)",
    )
    ap.add_argument("--realtime", action="store_true", help="through the CLI in real time (bench/realtime.py)")
    add_realtime_options(ap)
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    loads = LOADS_QUICK if args.quick else LOADS_QUICK + LOADS_MORE
    ratios = [5.0] if args.quick else [2.0, 10.0]
    if args.realtime:
        from realtime import off_model_table

        rows = args.rows or REALTIME_ROWS
        off_model_table(
            rows, loads, ratios, args.seeds, burner=args.burner, tcp_port=args.tcp_port, verbose=args.verbose
        )
        return
    bauds = args.baud or ([19200] if args.quick else [19200, 115200])
    if args.seeds > 1:
        print(f"{'load':<22} {'ratio':>5} {'baud':>6} {'acc':>4} {'flag':>4} {'ref':>4} {'viol':>4}  worst err/3sig")
    else:
        print(f"{'load':<22} {'ratio':>5} {'baud':>6} {'outcome':<9} {'err%':>7} {'3sig%':>6}  reason / flags")
    violations = counted = runs = n = 0
    outcomes: dict[str, int] = {}
    rows = [(label, machine, ratio, 0.002) for label, machine in loads for ratio in ratios]
    heavy = [] if args.quick else HEAVY
    for baud in bauds:
        for h, (label, machine, ratio, noise) in enumerate(rows + heavy):
            if h < len(rows):
                n += 1  # the rows' seeds as before the heavy ones came
            seed = n if h < len(rows) else 500 + h
            row: dict[str, int] = {}
            worst, row_violations = 0.0, 0
            for k in range(args.seeds):
                runs += 1
                outcome, err, sig3, why = outcome_of(ratio, machine, baud, seed + 1000 * k, args.profile, noise)
                outcomes[outcome] = outcomes.get(outcome, 0) + 1
                row[outcome] = row.get(outcome, 0) + 1
                bad = ""
                if outcome in ("accepted", "flagged"):
                    counted += 1
                    worst = max(worst, abs(err) / sig3 if sig3 > 0 else float("inf"))
                    if abs(err) > sig3:
                        row_violations += 1
                        bad = "  <-- outside 3 sigma"
                if args.seeds == 1:
                    print(
                        f"{label:<22} {ratio:>5.1f} {baud:>6} {outcome:<9} {err:>7.2f} {sig3:>6.2f}  {why[:110]}{bad}",
                        flush=True,
                    )
            violations += row_violations
            if args.seeds > 1:
                print(
                    f"{label:<22} {ratio:>5.1f} {baud:>6} {row.get('accepted', 0):>4} {row.get('flagged', 0):>4} "
                    f"{row.get('refused', 0) + row.get('failed', 0):>4} {row_violations:>4}  {worst:.2f}"
                    f"{'  <-- outside 3 sigma' if row_violations else ''}",
                    flush=True,
                )
    print("\n" + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    print(
        f"no accepted result off by more than its stated 3 sigma: {violations} violation(s) in {counted} "
        f"accepted or flagged of {runs} runs: {'met' if violations == 0 else 'MISSED'}"
    )


if __name__ == "__main__":
    main()
