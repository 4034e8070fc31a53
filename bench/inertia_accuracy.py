"""Accuracy of `tune inertia` (host method) on the simulated drive over a grid of machines and line speeds.

`tune inertia` itself (tuning.tune.tune_inertia: checks, rest check, motion planned from the measured sampling
rate, pilot, adaptive repeats, fit; a dry run, so nothing is written) runs against the simulated drive's registers
and firmware on virtual time; each request costs the RS485 wire time of its frames at the given baud, so 19200 baud
samples as slowly as a real bus. A gravity axis (load torque above friction) gets a holding brake, as a real
vertical axis has: without one it falls as soon as the servo is off and tune inertia refuses it before moving.

Prints per run: true ratio, estimate, error % of J_total, the reported 1-sigma uncertainty (% of J_total), travel,
time, samples/s; a refusal is printed as a row with its reason and counts as a failure of the targets.
Targets: median |error| <= 2 %, worst <= 5 %, travel <= 2 rev, time <= 10 s, no refusals; and the reported
uncertainty should bound the error (|error| <= 3 sigma).

Run: python bench/inertia_accuracy.py [--quick]
     python bench/inertia_accuracy.py --profiles [--quick] [--remedies]
--profiles: all four profiles at their factory line speed (SD25 9600 8N1, SDC 9600 8O1, IS620P 57600, DSX7E 115200)
and at 19200, through tune_inertia as the CLI runs it (its motion route, hold and keep-alive; drives without a
dead-man route moved as with --no-dead-man), over a seeded sample of issue 16's machines (loads 0-50, Coulomb up to
30 % of rated, viscous, gravity +-40 % on a braked axis, noise up to 1 %); --quick: 14 machines per row, a few
minutes; else 60. Targets per row (issue 16): accepted >= 95 % (a refusal is a miss; reasons are printed grouped),
median |error of J_total| <= 1 %, worst <= 3 %, the true value within the reported 3 sigma in >= 95 %, each run
within 2 rev and 10 s; and the identification samples at >= 0.8x what the line carries for speed and torque back
to back ('share'). The wire time counts 11 bits a character whatever the format (8N1 is 10: a real 8N1 line is
about 10 % faster than modelled).
--remedies (with --profiles): every refusal that suggests a longer travel (tuning.planning.Remedy) is run again
with it, as a user following the advice would, in a second table: refusals, those with a travel suggested (and
said to be enough), accepted when followed, within their 3 sigma, their error and the travels suggested.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import random
import re
import statistics
import sys
import tempfile
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from servotool.clock import VirtualClock
from servotool.drive import Drive, coalesce_reads
from servotool.errors import ServoError
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.plant import Plant
from servotool.sim.virtual import TURNAROUND_S, HostStalls, VirtualLink, make_motion_setup, wire_time
from servotool.tuning.errors import TravelNeeded
from servotool.tuning.identify import IdentificationRefused
from servotool.tuning.tune import TuneRequest, TuneResult, tune_inertia

TRAVEL_REV = 2.0
# The simulated DSX7E's 500 ms host watchdog lets a dead host's motor run on 9 rev at 1080 rpm: 2 rev of travel leave
# it 184 rpm (tuning.planning.fit_run_on), too little to identify; its rows get the travel its run-on needs.
DSX7E_TRAVEL_REV = 12.0


def bench_travel(profile_id: str) -> float:
    """The travel limit a bench row identifies within: 2 rev, or what the drive's dead-man run-on needs."""
    return DSX7E_TRAVEL_REV if profile_id == "dsx7e" else TRAVEL_REV


def fit_brake(plant: Plant) -> None:
    """A holding brake that also stops the axis the instant the servo goes off (bench/off_model.py's loads; the
    --profiles table uses the simulator's own brake, as the CLI sees it)."""
    step = plant._step

    def braked() -> None:
        if plant.mode == "off":
            plant.w = plant._w_meas = 0.0
            plant._t_applied = plant._t_filtered = plant._t_cmd = plant._t_delayed = 0.0
            return
        step()

    plant._step = braked  # type: ignore[method-assign]


FACTORY_BAUD = {"sd25": 9600, "sdc": 9600, "is620p": 57600, "dsx7e": 115200}

# Issue 16's machines: loads 0-50, Coulomb friction up to 30 % of rated, viscous friction, gravity +-40 %, noise up
# to 1 %. A run draws one level of each (seeded); gravity runs on a braked axis, as the sim's brake does by default.
LOADS = [0.0, 1.0, 5.0, 10.0, 20.0, 37.0, 50.0]
COULOMB = [0.01, 0.05, 0.1, 0.2, 0.3]
VISCOUS = [0.0, 0.0005, 0.001]  # fraction of rated torque per rad/s
GRAVITY = [-0.4, -0.2, 0.0, 0.2, 0.4]
NOISE = [0.0, 0.002, 0.005, 0.01]


def identify_once(
    ratio: float,
    friction: float,
    gravity: float,
    noise: float,
    baud: int,
    seed: int,
    brake: bool = True,
    profile_id: str = "dsx7e",
    viscous: float = 0.0005,
    travel_rev: float | None = None,
    follow: bool = True,
    stalls: HostStalls | None = None,
) -> TuneResult:
    """`tune inertia` with the CLI's defaults (identify and report: a dry run) on one simulated machine; a drive
    without a dead-man route is moved as the CLI moves it with --no-dead-man. follow: where it names the travel the
    line needs (TravelNeeded: before moving, or after the pilot), it runs once more with it, as a user does. A
    travel_rev given (and a travel followed) is the user's --travel; None: the bench's default, as if not given."""
    profile = load_profile(profile_id)

    def attempt(travel: float, given: bool) -> TuneResult:
        clock = VirtualClock(1000.0)
        sim = build_drive(profile, 1, clock, persist=False)
        sim.settings.update(
            load_ratio=ratio,
            friction=friction,
            viscous=viscous,
            load_torque=gravity,
            noise=noise,
            seed=seed,
            brake=1 if brake else 0,
        )
        sim.firmware.reconfigure()
        make_motion_setup(sim)
        drive = Drive(VirtualLink([sim], clock, baud, stalls), profile, 1)
        drive.dead_man_waived = True
        request = TuneRequest(travel_rev=travel, travel_given=given, dry_run=True)
        return tune_inertia(drive, request, clock=clock)

    used = travel_rev if travel_rev is not None else bench_travel(profile_id)
    try:
        return attempt(used, travel_rev is not None)
    except TravelNeeded as exc:
        if not follow or not math.isfinite(exc.travel_rev) or exc.travel_rev <= used:
            raise
        return attempt(exc.travel_rev, True)


def line_rate(profile_id: str, baud: int) -> float:
    """Samples/s the line carries for the estimator's entries (speed and torque, in as few requests as the profile
    allows), back to back with nothing else on the line."""
    p = load_profile(profile_id)
    entries = [p.need_role("speed_feedback", "bench"), p.need_role("torque_feedback", "bench")]
    return 1.0 / sum(wire_time(3, count, baud) + TURNAROUND_S for _a, count, _g in coalesce_reads(p, entries))


def reason_of(exc: ServoError) -> str:
    """A refusal's reason without its figures, to group them."""
    text = str(exc).removeprefix("identification refused: ")
    return re.sub(r"[-+]?\d+(\.\d+)?", "N", text.split(";")[0].split(": use")[0])[:90]


@dataclass
class Cell:
    """The runs of one profile at one baud."""

    profile: str
    baud: int
    runs: int = 0
    errors: list[float] = field(default_factory=list)  # |error| % of J_total, accepted runs
    within: int = 0  # true value within the reported 3 sigma
    within2: int = 0  # ... within twice it
    over: int = 0  # over the travel and time named before moving (2 rev and 10 s where none was named)
    named: list[float] = field(default_factory=list)  # the travels servotool named and the run was repeated with
    rates: list[float] = field(default_factory=list)
    reasons: Counter[str] = field(default_factory=Counter)

    def add(self, ratio: float, run: TuneResult | ServoError) -> None:
        self.runs += 1
        if isinstance(run, ServoError):
            self.reasons[reason_of(run)] += 1
            return
        est = run.identified.estimate
        assert est is not None
        err = abs(run.ratio - ratio) / (1.0 + ratio) * 100
        self.errors.append(err)
        self.within += abs(run.ratio - ratio) <= 3 * est.ratio_std + 1e-9
        self.within2 += abs(run.ratio - ratio) <= 6 * est.ratio_std + 1e-9
        plan = run.identified.plan  # the travel it was given, the most time it was to take as said before moving
        travel, named_s = (plan.travel_limit_rev, plan.time_limit_s) if plan is not None else (TRAVEL_REV, 10.0)
        if travel > TRAVEL_REV:
            self.named.append(travel)
        self.over += (run.identified.travel_used_rev or 0.0) > travel or run.identified.time_used_s > named_s + 0.5
        self.rates.append(run.identified.samples_per_s)

    def targets(self) -> dict[str, bool]:
        n, ok = self.runs, len(self.errors)
        return {
            "accepted >= 95 %": ok >= 0.95 * n,
            "median <= 1 %": ok > 0 and statistics.median(self.errors) <= 1,
            "worst <= 3 %": ok > 0 and max(self.errors) <= 3,
            "in 3 sigma >= 95 %": ok > 0 and self.within >= 0.95 * ok,
            "none beyond 2x 3 sigma": self.within2 == ok,
            "within the named travel and time": ok > 0 and self.over == 0,
        }

    def row(self) -> str:
        ok, e = len(self.errors), self.errors
        line = line_rate(self.profile, self.baud)
        rate = statistics.median(self.rates) if self.rates else 0.0
        unmet = [k for k, v in self.targets().items() if not v]
        return (
            f"{self.profile:>7} {self.baud:>6} {self.runs:>4} {ok:>4} {ok / self.runs:>4.0%} "
            f"{statistics.median(e) if e else math.nan:>7.2f} {max(e) if e else math.nan:>7.2f} "
            f"{self.within:>3}/{ok:<3} {self.over:>4} {rate:>6.0f} {line:>6.0f} {rate / line:>5.2f} "
            f"{(f'{min(self.named):g}-{max(self.named):g}' if self.named else '-'):>9}  "
            + ("met" if not unmet else "UNMET: " + ", ".join(unmet))
        )


def draws(quick: bool, seed: int = 16, count: int | None = None) -> list[tuple[float, float, float, float, float]]:
    """The machines of one cell: a seeded sample of the grid (the same for every profile and baud)."""
    rng = random.Random(seed)
    grid = list(itertools.product(LOADS, COULOMB, VISCOUS, GRAVITY, NOISE))
    return rng.sample(grid, count or (14 if quick else 60))


@dataclass
class Remedies:
    """The refusals of one cell that suggest a longer travel (tuning.planning.Remedy), run again with it."""

    profile: str
    baud: int
    refused: int = 0
    given: int = 0
    enough: int = 0  # the remedy said it should be enough
    accepted: list[tuple[float, bool, float]] = field(default_factory=list)  # |error| %, within 3 sigma, travel

    def follow(self, refusal: IdentificationRefused, true: float, rerun: Callable[[float], TuneResult]) -> None:
        self.refused += 1
        cure = refusal.remedy
        if cure is None:
            return
        self.given += 1
        self.enough += cure.enough
        try:
            run = rerun(cure.suggested_rev)
        except ServoError:
            return
        est = run.identified.estimate
        assert est is not None
        self.accepted.append(
            (abs(run.ratio - true) / (1.0 + true) * 100, abs(run.ratio - true) <= 3 * est.ratio_std, cure.suggested_rev)
        )

    def row(self) -> str:
        ok = self.accepted
        errors = [e for e, _w, _t in ok]
        travels = [t for _e, _w, t in ok]
        return (
            f"{self.profile:>7} {self.baud:>6} {self.refused:>7} {self.given:>6} {self.enough:>6} "
            f"{len(ok):>8} {sum(w for _e, w, _t in ok):>3}/{len(ok):<3} "
            f"{statistics.median(errors) if errors else math.nan:>7.2f} {max(errors) if errors else math.nan:>7.2f}"
            f" {statistics.median(travels) if travels else math.nan:>6.1f} {max(travels, default=math.nan):>6.1f}"
        )


def run_cell(
    pid: str, baud: int, machines: list[tuple[float, float, float, float, float]], remedies: bool
) -> tuple[Cell, Remedies]:
    """One row of the --profiles table, and (for the remedies table) the refusals' suggested travels followed."""
    cell, followed = Cell(pid, baud), Remedies(pid, baud)
    for n, (ratio, fr, visc, gr, nz) in enumerate(machines):
        try:
            run: TuneResult | ServoError = identify_once(
                ratio, fr, gr, nz, baud, seed=n + 1, profile_id=pid, viscous=visc
            )
        except ServoError as exc:
            run = exc
        cell.add(ratio, run)
        if remedies and isinstance(run, IdentificationRefused):
            followed.follow(
                run,
                ratio,
                lambda travel, m=(ratio, fr, visc, gr, nz), n=n: identify_once(
                    m[0], m[1], m[3], m[4], baud, seed=n + 1, profile_id=pid, viscous=m[2], travel_rev=travel
                ),
            )
    return cell, followed


def profiles_table(
    quick: bool,
    remedies: bool = False,
    rows: list[tuple[str, int]] | None = None,
    seed: int = 16,
    count: int | None = None,
) -> bool:
    """Every profile at its factory line speed and at 19200 (and SD25 at 57600, its boosted line) through
    tune_inertia, or the rows given; returns whether all targets met. remedies: each refusal that suggests a longer
    travel is run again with it (a second table). seed, count: the machines drawn (draws)."""
    machines = draws(quick, seed, count)
    print(
        f"{len(machines)} machines per row (seeded sample of loads {LOADS}, Coulomb {COULOMB} x rated, viscous "
        f"{VISCOUS} x rated per rad/s, gravity {GRAVITY} x rated, noise {NOISE})"
    )
    print(
        f"{'profile':>7} {'baud':>6} {'runs':>4} {'accepted':>9} {'median%':>7} {'worst%':>7} {'in3sig':>7} "
        f"{'over':>4} {'samp/s':>6} {'line/s':>6} {'share':>5} {'named rev':>9}  targets"
    )
    cells, followed = [], []
    every = rows or [
        (pid, baud)
        for pid, factory in FACTORY_BAUD.items()
        for baud in sorted({factory, 19200} | ({57600} if pid == "sd25" else set()), reverse=True)
    ]
    for pid, baud in every:
        cell, remedied = run_cell(pid, baud, machines, remedies)
        print(cell.row(), flush=True)
        cells.append(cell)
        followed.append(remedied)
    print("\nrefusals (each counts as a miss):")
    for cell in cells:
        for reason, count in cell.reasons.most_common():
            print(f"  {cell.profile:>7} {cell.baud:>6} {count:>3} x {reason}")
    if remedies:
        print(
            "\nrefusals that suggest a longer travel, run again with it (issue 16: the remedy a refusal names must "
            "help):"
        )
        print(
            f"{'profile':>7} {'baud':>6} {'refused':>7} {'travel':>6} {'enough':>6} {'accepted':>8} {'in3sig':>7} "
            f"{'median%':>7} {'worst%':>7} {'med_rev':>6} {'max_rev':>6}"
        )
        for remedied in followed:
            print(remedied.row())
        accepted = [a for remedied in followed for a in remedied.accepted]
        print(
            f"all rows: {sum(r.given for r in followed)} travels suggested, {len(accepted)} accepted when "
            f"followed, {sum(w for _e, w, _t in accepted)} of them within their 3 sigma"
        )
    met = all(all(c.targets().values()) for c in cells)
    print(
        "targets (accepted >= 95 %, median <= 1 %, worst <= 3 %, in 3 sigma >= 95 %, none beyond twice it, within "
        "the travel and time named before moving ('over': beyond them; a travel named after the pilot is followed "
        "once, 'named rev'); 'share': identification samples/s over what the line carries for speed and torque, "
        "target >= 0.8): " + ("all met" if met else "NOT all met")
    )
    return met


# Real time (--realtime): each profile at its factory line, as shipped; servotool raises SD25's 9600 baud for the
# identification itself (issue 31 item 1: Po504, `sim serve` follows it as the manual has it).
REALTIME_ROWS = [("sd25", 9600), ("sdc", 9600), ("is620p", 57600), ("dsx7e", 115200)]


def parse_rows(text: str) -> list[tuple[str, int]]:
    """'sd25:57600,sdc:9600' -> [("sd25", 57600), ("sdc", 9600)]."""
    rows = []
    for item in text.split(","):
        pid, _, baud = item.partition(":")
        rows.append((pid.strip(), int(baud) if baud else FACTORY_BAUD[pid.strip()]))
    return rows


def add_realtime_options(ap: argparse.ArgumentParser) -> None:
    """The options every real-time bench shares (--rows, --burner, --tcp-port, -v)."""
    ap.add_argument(
        "--rows",
        type=parse_rows,
        default=None,
        help="with --realtime: PROFILE:BAUD,... (default: " + ",".join(f"{p}:{b}" for p, b in REALTIME_ROWS) + ")",
    )
    ap.add_argument("--burner", action="store_true", help="with --realtime: one CPU-burning process beside it")
    ap.add_argument("--tcp-port", type=int, default=0, help="with --realtime: sim serve's port (0: any free one)")
    ap.add_argument("-v", "--verbose", action="store_true", help="with --realtime: each run's outcome")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a smaller grid")
    ap.add_argument(
        "--realtime",
        action="store_true",
        help="through the CLI in real time against `sim serve` in its own process (bench/realtime.py)",
    )
    add_realtime_options(ap)
    ap.add_argument("--embedded", action="store_true", help="with --realtime: --port sim (the simulator in-process)")
    ap.add_argument(
        "--machines", type=int, default=None, help="with --realtime: machines per row (default 14, 60 without --quick)"
    )
    ap.add_argument(
        "--draw-seed",
        type=int,
        default=16,
        help="seed of the machines drawn (16: the bench's own; another: a set it has never used)",
    )
    ap.add_argument("--profiles", action="store_true", help="every profile at its factory line speed and 19200")
    ap.add_argument(
        "--remedies",
        action="store_true",
        help="with --profiles: run each refusal that suggests a longer travel again with it",
    )
    args = ap.parse_args()
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    if args.realtime:
        from realtime import realtime_table

        count = args.machines or (14 if args.quick else 60)
        machines = draws(args.quick, args.draw_seed, count)
        realtime_table(
            args.rows or REALTIME_ROWS,
            machines,
            line_rate,
            burner=args.burner,
            embedded=args.embedded,
            tcp_port=args.tcp_port,
            verbose=args.verbose,
        )
        return
    if args.profiles:
        profiles_table(args.quick, args.remedies, args.rows, args.draw_seed, args.machines)
        return
    ratios = [0.0, 3.0, 20.0, 50.0] if args.quick else [0.0, 1.0, 3.0, 10.0, 20.0, 35.0, 50.0]
    frictions = [0.02] if args.quick else [0.01, 0.05]
    gravities = [0.0, 0.1]
    noises = [0.002] if args.quick else [0.001, 0.004]
    bauds = [19200, 115200]
    print(
        f"{'baud':>6} {'true':>6} {'fric':>5} {'grav':>5} {'noise':>6} {'est':>8} {'err%':>7} {'sigma%':>7} "
        f"{'travel':>7} {'time_s':>7} {'samp/s':>7}"
    )
    rows: dict[int, list[tuple[float, float, float, float]]] = {b: [] for b in bauds}
    refused: dict[int, int] = dict.fromkeys(bauds, 0)
    for n, (baud, ratio, fr, gr, nz) in enumerate(itertools.product(bauds, ratios, frictions, gravities, noises)):
        head = f"{baud:>6} {ratio:>6.1f} {fr:>5.2f} {gr:>5.2f} {nz:>6.3f}"
        try:
            r = identify_once(ratio, fr, gr, nz, baud, seed=n + 1)
        except ServoError as exc:
            refused[baud] += 1
            print(f"{head}  REFUSED: {exc}")
            continue
        ident = r.identified
        assert ident.estimate is not None
        # error relative to the total inertia the loop sees (ratio 0 has no relative error of its own)
        err = (r.ratio - ratio) / (1.0 + ratio) * 100
        sigma = ident.estimate.ratio_std / (1.0 + r.ratio) * 100
        travel = ident.travel_used_rev or 0.0
        rows[baud].append((abs(err), sigma, travel, r.seconds))  # the whole run, rest check included
        print(
            f"{head} {r.ratio:>8.3f} {err:>7.2f} {sigma:>7.2f} {travel:>7.2f} {r.seconds:>7.2f} "
            f"{ident.samples_per_s:>7.1f}"
        )
    print()
    met = True
    for baud in bauds:
        ok, total = rows[baud], len(rows[baud]) + refused[baud]
        if not ok:
            print(f"{baud:>6} baud: runs {total}, refused {refused[baud]}")
            met = False
            continue
        errors = [e for e, *_ in ok]
        within = sum(1 for e, s, *_ in ok if e <= 3 * s)
        worst_travel, worst_time = max(x[2] for x in ok), max(x[3] for x in ok)
        line_met = (
            refused[baud] == 0
            and statistics.median(errors) <= 2
            and max(errors) <= 5
            and worst_travel <= TRAVEL_REV
            and worst_time <= 10
        )
        met &= line_met
        print(
            f"{baud:>6} baud: runs {total}, refused {refused[baud]}; |error| of J_total: median "
            f"{statistics.median(errors):.2f} %, worst {max(errors):.2f} %; error within 3 sigma {within}/{len(ok)};"
            f" worst travel {worst_travel:.2f} rev, worst time {worst_time:.1f} s: "
            f"{'targets met' if line_met else 'TARGETS MISSED'}"
        )
    print("targets (median <= 2 %, worst <= 5 %, <= 2 rev, <= 10 s, no refusals): " + ("met" if met else "MISSED"))


if __name__ == "__main__":
    main()
