"""Does servotool ever accept a wrong value on a bad line? Param get, set, backup, restore, monitor-like and
trace-like reads through the real client path (RtuMaster + Drive, RTU over TCP) to simulated drives behind a
fault-injecting line (servotool.sim.faults), at 1, 5 and 20 % of replies for each fault kind and mixed, and with
writes to 1, 5 and 20 % of the settable entries acknowledged but ignored, on every profile. Every value is checked
against the simulator's true state; a restore that fails must not claim a state the drive is not in.

Run: python bench/line_faults.py [--quick] [--tries N] [--seed S] [--profile P ...] [--clean N]
Prints one row per fault kind, rate and operation (profiles summed): tries, ok, clean error, silent wrong,
traceback, hang. The target is silent wrong = 0 everywhere. --clean N instead times each operation N times on a
clean line per profile (ms per operation, the median), to compare the link's cost before and after a change.
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import tempfile
import threading
import time
import traceback
from collections import Counter
from collections.abc import Callable

from servotool.drive import Drive
from servotool.errors import ServoError, VerifyError
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.codec import words_to_raw
from servotool.model.loader import load_profile
from servotool.model.profile import Entry, Profile
from servotool.ops import backup, monitor, restore
from servotool.ops.trace import motion_entries
from servotool.sim.device import SimulatedDrive
from servotool.sim.faults import KINDS, LineFaults, parse_rates
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim

PROFILES = ("sd25", "is620p", "sdc", "dsx7e")
FAULTS = (*KINDS, "mixed", "mixed+echo", "ignored")  # ignored: writes to RATE of the settable entries
RATES = (0.01, 0.05, 0.20)
OPS = ("get", "set", "backup", "restore", "monitor", "trace")
OUTCOMES = ("ok", "error", "WRONG", "traceback", "hang")
TIMEOUT_S, LATE_S, HANG_S = 0.1, 0.15, 30.0  # late replies come after the timeout, within the late window
VERBOSE = False
ACCOUNTS: Counter[str] = Counter()  # failed restores by the drive state they stated: equal, differ, unknown


class Wrong(Exception):
    """A value the client accepted differs from the drive's true state."""


class Bench:
    """One profile's simulated drive behind a bad line, and the checks of each operation against it."""

    def __init__(self, profile: Profile, seed: int) -> None:
        self.profile = profile
        self.sim_drive: SimulatedDrive = build_drive(profile, profile.default_unit, persist=False)
        self.sim_drive.configure(noise=0.0)  # at rest with no noise, live values hold still
        self.sim_drive.firmware.reconfigure()  # type: ignore[attr-defined]
        self.sim = EmbeddedSim([self.sim_drive], LineFaults())
        self.rng = random.Random(seed)
        roles = {c.upper() for c in profile.roles.values()}
        self.params = [e for e in profile.of_class("Pn") if e.readable]
        self.settable = [
            e
            for e in self.params
            if e.writable
            and e.code.upper() not in roles
            and not e.fields
            and not e.enum
            and not e.bits
            and e.max > e.min
        ]
        self.monitors = monitor.default_entries(profile)
        self.traced = motion_entries(profile)

    def truth(self, entry: Entry) -> int:
        assert self.sim.proxy is not None
        with self.sim.lock:
            return words_to_raw(entry, self.sim_drive.read(entry.address, entry.words))

    def check(self, entry: Entry, raw: int) -> None:
        if (true := self.truth(entry)) != raw:
            raise Wrong(f"{entry.code}: accepted {raw}, drive holds {true}")

    def get(self, drive: Drive) -> None:
        for r in drive.read_entries(self.rng.sample(self.params, 4)):
            self.check(r.entry, r.raw)

    def set(self, drive: Drive) -> None:
        entry = self.rng.choice(self.settable)
        raw = self.rng.randint(entry.min, entry.max)
        try:
            result = drive.write_verified(entry, raw)
        except VerifyError as exc:
            if self.truth(entry) == raw:
                raise Wrong(f"false verify error: {exc}") from None
            raise
        self.check(entry, result.new)

    def backup(self, drive: Drive) -> None:
        taken = backup.take(drive)
        for e in self.params:
            self.check(e, taken.values[e.code])

    def monitor(self, drive: Drive) -> None:
        for _ in range(8):
            for r in drive.read_entries(self.monitors):
                self.check(r.entry, r.raw)

    def trace(self, drive: Drive) -> None:
        for _ in range(16):
            for r in drive.read_entries(self.traced):
                self.check(r.entry, r.raw)

    def restore(self, drive: Drive) -> None:
        """A backup that differs in a few entries, restored; a failed restore's account of the drive (equal to the
        automatic backup, or which entries differ) is checked against the drive's true state."""
        truth = {e.code: self.truth(e) for e in self.params}
        values = dict(truth)
        for e in self.rng.sample(self.settable, 4):
            values[e.code] = self.rng.randint(e.min, e.max)
        p = self.profile
        b = backup.Backup(p.id, p.version, p.model, drive.unit, "", "", {}, values)
        plan = restore.restore_changes(p, b, truth)
        try:
            restore.restore(drive, b, plan)
        except restore.RestoreFailed as exc:
            auto = backup.load(exc.auto_backup, p).values
            differ = {c for c, v in auto.items() if self.truth(p.entry(c)) != v and not p.persistence.is_switch(c)}
            if exc.equals_backup is None:
                ACCOUNTS["unknown"] += 1
            elif exc.equals_backup != (not differ) or (differ and set(exc.differ) != differ):
                raise Wrong(f"restore account wrong: said {exc.facts()!r}; truly differ {sorted(differ)}") from None
            else:
                ACCOUNTS["equal" if not differ else "differ"] += 1
            raise
        except ServoError as exc:  # before any write: it must say so, and be true
            now = {e.code: self.truth(e) for e in self.params}
            if "nothing was written" not in str(exc) or now != truth:
                raise Wrong(
                    f"restore failed before writing? said {exc}; changed {sorted(c for c in now if now[c] != truth[c])}"
                ) from None
            ACCOUNTS["nothing written"] += 1
            raise
        for e, _, new in plan.changes:
            self.check(e, new)

    def run(self, op: str, faults: LineFaults) -> str:
        """One try of op on a fresh link: its outcome (one of OUTCOMES)."""
        assert self.sim.proxy is not None
        self.sim.proxy.set_faults(faults)
        link = RtuMaster(LinkSettings(self.sim.port, timeout=TIMEOUT_S, retries=2, echo=None if faults.echo else False))
        drive = Drive(link, self.profile, self.profile.default_unit)
        outcome = _guarded(lambda: getattr(self, op)(drive))
        if outcome != "hang":
            link.close()
        return outcome

    def close(self) -> None:
        self.sim.close()


def _guarded(fn: Callable[[], None]) -> str:
    result: list[str] = []

    def body() -> None:
        try:
            fn()
            result.append("ok")
        except Wrong as exc:
            print(f"  WRONG: {exc}", file=sys.stderr)
            result.append("WRONG")
        except ServoError as exc:
            if VERBOSE:
                print(f"  error: {exc}", file=sys.stderr)
            result.append("error")
        except Exception:
            traceback.print_exc()
            result.append("traceback")

    worker = threading.Thread(target=body, daemon=True)
    worker.start()
    worker.join(HANG_S)
    return result[0] if result else "hang"


def line(kind: str, rate: float, seed: int, settable: list[Entry]) -> LineFaults:
    if kind == "ignored":
        rng = random.Random(seed)
        ignored = rng.sample(settable, max(1, round(rate * len(settable))))
        return LineFaults(seed=seed, ignore_writes=frozenset(a for e in ignored for a in e.addresses))
    spec = "mixed" if kind.startswith("mixed") else kind
    return LineFaults(parse_rates(f"{spec}:{rate}"), seed=seed, late_s=LATE_S, echo=kind.endswith("+echo"))


def clean(n: int) -> None:
    """Each operation n times on a clean line, per profile: the median ms per operation."""
    print(f"{'profile':<8} " + " ".join(f"{op:>9}" for op in OPS) + f"   (ms per operation, median of {n})")
    for profile_id in PROFILES:
        bench = Bench(load_profile(profile_id), 1)
        times = []
        try:
            for op in OPS:
                took = []
                for _ in range(n):
                    t0 = time.perf_counter()
                    assert bench.run(op, LineFaults()) == "ok"
                    took.append((time.perf_counter() - t0) * 1000)
                times.append(statistics.median(took))
        finally:
            bench.close()
        print(f"{profile_id:<8} " + " ".join(f"{t:>9.1f}" for t in times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a short sample: 20 %% only, one profile per fault kind")
    ap.add_argument("--tries", type=int, default=1, help="tries per profile, fault kind, rate and operation")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--profile", action="append", choices=PROFILES, help="only these profiles (repeatable)")
    ap.add_argument("-v", "--verbose", action="store_true", help="print each clean error")
    ap.add_argument("--clean", type=int, metavar="N", help="time each operation N times on a clean line instead")
    args = ap.parse_args()
    global VERBOSE
    VERBOSE = args.verbose
    os.environ.setdefault("SERVOTOOL_SIM_DIR", tempfile.mkdtemp())
    os.environ.setdefault("SERVOTOOL_BACKUP_DIR", tempfile.mkdtemp())  # the restores' automatic backups
    if args.clean:
        clean(args.clean)
        return
    rates = (0.20,) if args.quick else RATES
    counts: dict[tuple[str, float, str], Counter[str]] = {}
    t0 = time.monotonic()
    for p_index, profile_id in enumerate(PROFILES):
        if args.profile and profile_id not in args.profile:
            continue
        bench = Bench(load_profile(profile_id), args.seed)
        try:
            for k_index, kind in enumerate(FAULTS):
                if args.quick and k_index % len(PROFILES) != p_index:
                    continue
                for rate in rates:
                    for op in OPS:
                        cell = counts.setdefault((kind, rate, op), Counter())
                        for t in range(args.tries):
                            faults = line(kind, rate, args.seed * 1000 + t, bench.settable)
                            cell[bench.run(op, faults)] += 1
        finally:
            bench.close()
    report(counts, time.monotonic() - t0)


def report(counts: dict[tuple[str, float, str], Counter[str]], elapsed: float) -> None:
    print(f"{'fault':<11} {'rate':>5} {'op':<8} {'tries':>5} " + " ".join(f"{o:>9}" for o in OUTCOMES))
    total: Counter[str] = Counter()
    for (kind, rate, op), cell in sorted(
        counts.items(), key=lambda kv: (FAULTS.index(kv[0][0]), kv[0][1], OPS.index(kv[0][2]))
    ):
        total.update(cell)
        print(f"{kind:<11} {rate:>5.0%} {op:<8} {sum(cell.values()):>5} " + " ".join(f"{cell[o]:>9}" for o in OUTCOMES))
    print(f"{'all':<11} {'':>5} {'':<8} {sum(total.values()):>5} " + " ".join(f"{total[o]:>9}" for o in OUTCOMES))
    print(f"silent wrong: {total['WRONG']} in {sum(total.values())} tries ({elapsed:.0f} s)")
    if ACCOUNTS:
        stated = ACCOUNTS["equal"] + ACCOUNTS["differ"] + ACCOUNTS["nothing written"]
        print(
            f"failed restores: {stated + ACCOUNTS['unknown']}, drive state stated and true in {stated} "
            f"(nothing written {ACCOUNTS['nothing written']}, rolled back to equal the automatic backup "
            f"{ACCOUNTS['equal']}, listed differences {ACCOUNTS['differ']}), 'unknown' (no answer) in "
            f"{ACCOUNTS['unknown']}; a wrong statement counts as WRONG above"
        )


if __name__ == "__main__":
    main()
