"""Does every way out of a motion leave the motor at rest, the servo as found and the bound kept? Ctrl-C (SIGINT to
the real CLI process) at random seeded moments of a JOG, an identification, a step check and `tune gains`, and
kill -9 during a JOG and an identification, on every profile, through `sim serve` on TCP; afterwards a plain Modbus
client (pymodbus' own, bench/plain_reader.py: none of servotool's link or recovery) reads the drive.

Pass, per run:
- Ctrl-C: once the command has exited, the speed reads under 10 rpm and the servo as found (off), the command's
  last line says so ("stopped, servo off", or before the motor moved "nothing moved: at rest, servo off") and its
  exit status is 130; after `tune gains`, the gains read as they
  were before it (the level being checked was rolled back).
- SD25 (forced DIs): forcing reads released (So-58.X = 0) after every exit, a Ctrl-C's and a stop's.
- kill -9: within the printed time (plus the reader's margin) the motor is at rest and has travelled at most the
  printed bound since the kill; a drive with no dead-man route (SD25, SDC: --no-dead-man) runs on, as the real one
  would, and `servotool stop` must then stop it (at rest, servo off, SD25's forcing released); the next command
  puts back what the dead one left (forcing released first).
- every identification: its planned travel plus the printed bound fit inside its --travel.

Run: python bench/ctrl_c_storm.py [--moments 20] [--kills 3] [--seed 1] [--profiles dsx7e,is620p,sd25,sdc]
         [--kinds jog,ident,step,gains] [--port-base 15150] [--older-trigger]
Prints one row per profile and kind: runs, passed, the slowest exit after the signal, the largest speed read
after exit, and for kills the largest travel against its bound.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from plain_reader import PlainReader, Snapshot

ROOT = Path(__file__).resolve().parent.parent
PROFILES = ("dsx7e", "is620p", "sd25", "sdc")
# The drive setup each profile's motion_setup asks for, as a user does it (None: a power cycle of the drive).
SETUP: dict[str, list[list[str] | None]] = {
    "dsx7e": [],
    "is620p": [
        ["param", "set", "H02-00=1", "H05-00=2", "H05-02=10000", "H11-00=0", "H0C-09=1", "H17-00=1", "H17-02=28"]
    ],
    "sdc": [["param", "set", "PN4=3"]],
    "sd25": [["param", "set", "--save", "Po407.X=26", "Po408.X=27"], None],  # servotool forces the DIs itself
}
GAINS = {"dsx7e": ("Pn101", "Pn102", "Pn100"), "is620p": ("H08-00", "H08-01", "H08-02")}
GAINS.update({"sd25": ("Po101", "Po102", "Po301"), "sdc": ("PN17", "PN18", "PN5")})
BOUND_RE = re.compile(r"motor stops within ([0-9.]+) rev \(([0-9.]+) s\)")
EXCURSION_RE = re.compile(r"([0-9.]+) rev of travel in all \(limit ([0-9.]+) rev\)")
REST_RPM = 10.0
# The last line of an interrupted motion command: its stop's read-back, or (before it moved) the read-back alone.
PROVEN = ("servotool: stopped", "servotool: nothing moved")
TRAVEL_REV = 6.0
COMMANDS: dict[str, list[str]] = {
    "jog": ["jog", "--speed", "300", "--time", "8", "--yes"],
    "ident": ["tune", "inertia", "--yes", "--dry-run", "--travel", str(TRAVEL_REV), "--max-speed", "600"],
    "step": [
        "tune",
        "inertia",
        "--yes",
        "--dry-run",
        "--step-check",
        "--travel",
        str(TRAVEL_REV),
        "--max-speed",
        "600",
    ],
    "gains": ["tune", "gains", "--yes", "--load-ratio", "2", "--travel", str(TRAVEL_REV)],
}
WINDOW_S = {"jog": 6.0, "ident": 4.0, "step": 1.2, "gains": 4.0}  # Ctrl-C lands this long after motion starts, at most


@dataclass
class Served:
    """One profile's simulated drive behind `sim serve` on TCP, with its own state folders."""

    profile: str
    root: Path
    port: str = ""
    proc: subprocess.Popen | None = None
    env: dict[str, str] = field(default_factory=dict)

    def start(self, port_number: int = 0) -> None:
        self.env = {
            **os.environ,
            "SERVOTOOL_SIM_DIR": str(self.root / "sim"),
            "SERVOTOOL_BACKUP_DIR": str(self.root / "bk"),
            "SERVOTOOL_CACHE_DIR": str(self.root / "cache"),
            "SERVOTOOL_CONFIG": str(self.root / "none.yaml"),
            "PYTHONPATH": str(ROOT),
            "COLUMNS": "200",
        }
        for var in ("SERVOTOOL_PORT", "SERVOTOOL_PROFILE", "SERVOTOOL_UNIT", "SERVOTOOL_BAUD"):
            self.env.pop(var, None)
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "servotool",
                "sim",
                "serve",
                "--port",
                f"tcp://127.0.0.1:{port_number}",
                "-P",
                self.profile,
            ],
            cwd=ROOT,
            env=self.env,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stderr is not None
        line = self.proc.stderr.readline()
        found = re.search(r"(tcp://127\.0\.0\.1:\d+)", line)
        if not found:
            raise RuntimeError(f"sim serve did not start: {line}")
        self.port = found.group(1)

    def restart(self) -> None:
        """A power cycle of the served drive (SD25's DI functions act after one)."""
        number = int(self.port.rsplit(":", 1)[1])
        self.close()
        self.start(number)

    def close(self) -> None:
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(timeout=10)
            self.proc = None

    def cli(self, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "servotool", "--port", self.port, "-P", self.profile, *args],
            cwd=ROOT,
            env=self.env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    def set_up(self, older_trigger: bool = False) -> None:
        if older_trigger and self.profile == "is620p":  # sim config --segment-restart on: the reading for comparison
            subprocess.run(
                [sys.executable, "-m", "servotool", "sim", "config", "-P", self.profile, "--segment-restart", "on"],
                cwd=ROOT,
                env=self.env,
                capture_output=True,
                check=True,
            )
        for args in SETUP[self.profile]:
            if args is None:
                self.restart()
                continue
            r = self.cli(*args)
            if r.returncode != 0:
                raise RuntimeError(f"{self.profile} setup failed: {r.stderr}")

    def read(self) -> Snapshot:
        with PlainReader(self.port, self.profile) as reader:
            return reader.snapshot()

    def gains(self) -> list[int]:
        with PlainReader(self.port, self.profile) as reader:
            return [reader.raw(reader.profile.entry(code)) for code in GAINS[self.profile]]

    def revolutions(self, before: int, after: int) -> float:
        with PlainReader(self.port, self.profile) as reader:
            return reader.revolutions(before, after)

    def tidy(self) -> None:
        """Between runs: a motor left running is stopped, an alarm a dead host's watchdog latched is cleared."""
        snap = self.read()
        if abs(snap.speed_rpm) >= REST_RPM or snap.servo_on:
            self.cli("stop", "--wait", "3")
        if snap.alarm:
            self.cli("alarm", "clear")


@dataclass
class Outcome:
    kind: str
    ok: bool
    why: str = ""
    exit_s: float = 0.0  # from the signal to the process's exit
    speed_rpm: float = 0.0  # read by the plain client after it
    moved_rev: float | None = None  # kill -9: travel after the kill
    bound_rev: float | None = None


def no_dead_man(profile: str) -> list[str]:
    from servotool.model.loader import load_profile
    from servotool.motion.deadman import route_of

    return ["--no-dead-man"] if route_of(load_profile(profile)).route == "none" else []


def _start(served: Served, kind: str) -> tuple[subprocess.Popen, list[str]]:
    """Start a motion command; returns once it printed its bound (it moves next), with the lines so far."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "--port",
            served.port,
            "-P",
            served.profile,
            *COMMANDS[kind],
            *no_dead_man(served.profile),
        ],
        cwd=ROOT,
        env=served.env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    lines: list[str] = []
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stderr.readline()
        if not line:
            break
        lines.append(line.rstrip())
        if ("rev (" in line and "stops within" in line) or "NO DEAD-MAN" in line:
            return proc, lines
    proc.kill()
    proc.wait()
    raise RuntimeError(f"{served.profile} {kind}: no bound printed: {lines[-3:]}")


def _fits(profile: str, lines: list[str]) -> str:
    """'' where the identification's planned travel and printed bound fit its --travel, else why not. On the segment
    route (IS620P) the bound is a single segment from where the host died, ending inside the planned travel: it
    alone must fit."""
    from servotool.model.loader import load_profile
    from servotool.motion.deadman import route_of

    motion = next((m for line in lines if (m := EXCURSION_RE.search(line))), None)
    bound = next((m for line in lines if (m := BOUND_RE.search(line))), None)
    if motion is None or bound is None:
        return ""
    travel, limit, rev = float(motion.group(1)), float(motion.group(2)), float(bound.group(1))
    need = rev if route_of(load_profile(profile)).route == "segment" else travel + rev
    return "" if need <= limit + 1e-6 else f"travel {travel} and bound {rev} do not fit the limit {limit}"


def interrupt(served: Served, kind: str, moment_s: float) -> Outcome:
    """Ctrl-C moment_s after the motion starts; the drive read by the plain client once the command exited."""
    gains_before = served.gains() if kind == "gains" else None
    found = served.read()
    proc, lines = _start(served, kind)
    time.sleep(moment_s)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    rest = proc.stderr.read() if proc.stderr is not None else ""
    status = proc.wait()
    exit_s = time.monotonic() - sent
    tail = [line for line in rest.splitlines() if line.strip()]
    snap = served.read()
    problems = []
    if status not in (0, 130):  # 0: it ended on its own just before the signal
        problems.append(f"exit {status}: {tail[-1] if tail else ''}")
    if abs(snap.speed_rpm) >= REST_RPM:
        problems.append(f"{snap.speed_rpm:g} rpm after exit")
    if snap.servo_on:
        problems.append("servo on after exit")
    if snap.forcing:  # SD25: the motion forced its DIs; released on every exit, the wired inputs act again
        problems.append(f"forcing reads {snap.forcing} after exit (was {found.forcing})")
    if status == 130 and not (tail and tail[-1].startswith(PROVEN)):
        problems.append(f"last line: {tail[-1] if tail else '(none)'}")
    if status == 130 and gains_before is not None and served.gains() != gains_before:
        problems.append(f"gains {served.gains()} after, {gains_before} before")
    if kind in ("ident", "step") and (why := _fits(served.profile, lines)):
        problems.append(why)
    served.tidy()
    return Outcome(kind, not problems, "; ".join(problems), exit_s, snap.speed_rpm)


def kill(served: Served, kind: str, moment_s: float) -> Outcome:
    """kill -9 moment_s after the motor turns; travel after it against the printed bound."""
    proc, lines = _start(served, kind)
    bound = next((m for line in lines if (m := BOUND_RE.search(line))), None)
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and abs(served.read().speed_rpm) < 50:
        time.sleep(0.02)
    time.sleep(moment_s)
    before = served.read()  # read first: the kill comes after, so this over-counts the travel
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    wait_s = float(bound.group(2)) if bound else 1.0
    time.sleep(wait_s + 0.5)
    after = served.read()
    moved = (
        abs(served.revolutions(before.position, after.position))
        if before.position is not None and after.position is not None
        else None
    )
    problems = []
    if bound is None:  # no dead-man: it runs on, as the real drive would; `servotool stop` must stop it
        if abs(after.speed_rpm) < REST_RPM and kind == "jog":
            problems.append("a drive without a dead-man stopped by itself")
        r = served.cli("stop")
        snap = served.read()
        if r.returncode != 0 or abs(snap.speed_rpm) >= REST_RPM or snap.servo_on or snap.forcing not in (None, 0):
            problems.append(f"servotool stop left {snap} (exit {r.returncode}: {r.stderr.strip()[-120:]})")
    else:
        limit = float(bound.group(1))
        if abs(after.speed_rpm) >= REST_RPM:
            problems.append(f"{after.speed_rpm:g} rpm {wait_s + 0.5:.2f} s after the kill")
        if moved is not None and moved > limit:
            problems.append(f"moved {moved:.2f} rev after the kill, bound {limit:.2f}")
    if kind == "ident" and (why := _fits(served.profile, lines)):
        problems.append(why)
    served.cli("param", "get", GAINS[served.profile][0])  # the next command puts back what the dead one left
    if served.read().forcing:
        problems.append("forcing still on after the next command (its journal releases it first)")
    served.tidy()
    return Outcome(
        f"kill {kind}",
        not problems,
        "; ".join(problems),
        0.0,
        after.speed_rpm,
        moved,
        float(bound.group(1)) if bound else None,
    )


def storm(
    profile: str,
    kinds: list[str],
    moments: int,
    kills: int,
    rng: random.Random,
    root: Path,
    port_number: int = 0,
    progress: Callable[[Outcome], None] | None = None,
    older_trigger: bool = False,
) -> list[Outcome]:
    """Every run for one profile, on a freshly served and set-up drive."""
    served = Served(profile, root)
    served.start(port_number)
    outcomes: list[Outcome] = []
    try:
        served.set_up(older_trigger)
        for kind in kinds:
            for _ in range(moments):
                outcomes.append(interrupt(served, kind, rng.uniform(0.05, WINDOW_S[kind])))
                if progress:
                    progress(outcomes[-1])
        for kind in ("jog", "ident"):
            for _ in range(kills):
                outcomes.append(kill(served, kind, rng.uniform(0.0, 1.0)))
                if progress:
                    progress(outcomes[-1])
    finally:
        served.close()
    return outcomes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--moments", type=int, default=20, help="Ctrl-C moments per profile and kind")
    ap.add_argument("--kills", type=int, default=3, help="kill -9 runs per profile, of a JOG and an identification")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--profiles", default=",".join(PROFILES))
    ap.add_argument("--kinds", default=",".join(COMMANDS))
    ap.add_argument("--port-base", type=int, default=0, help="first TCP port (one per profile); 0: any free one")
    ap.add_argument(
        "--older-trigger", action="store_true", help="IS620P: the older segment trigger reading (--segment-restart on)"
    )
    args = ap.parse_args()
    rng = random.Random(args.seed)
    kinds = [k for k in args.kinds.split(",") if k]
    print(f"load {os.getloadavg()[0]:.1f}, seed {args.seed}, {args.moments} Ctrl-C moments, {args.kills} kills")
    print(f"{'profile':8} {'run':11} {'runs':>5} {'pass':>5} {'exit s max':>10} {'rpm max':>8} {'kill rev/bound':>15}")
    failures: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for n, profile in enumerate(p for p in args.profiles.split(",") if p):
            port = args.port_base + n if args.port_base else 0
            outcomes = storm(
                profile,
                kinds,
                args.moments,
                args.kills,
                rng,
                Path(tmp) / profile,
                port,
                older_trigger=args.older_trigger,
            )
            for kind in dict.fromkeys(o.kind for o in outcomes):
                rows = [o for o in outcomes if o.kind == kind]
                worst = max(rows, key=lambda o: (o.moved_rev or 0.0) / (o.bound_rev or 1.0))
                kill_col = (
                    f"{worst.moved_rev:.2f}/{worst.bound_rev:.2f}"
                    if worst.moved_rev is not None and worst.bound_rev is not None
                    else ("runs on" if kind.startswith("kill") else "")
                )
                print(
                    f"{profile:8} {kind:11} {len(rows):5} {sum(o.ok for o in rows):5} "
                    f"{max(o.exit_s for o in rows):10.2f} {max(abs(o.speed_rpm) for o in rows):8.1f} {kill_col:>15}"
                )
                failures += [f"{profile} {o.kind}: {o.why}" for o in rows if not o.ok]
    for line in failures:
        print("FAIL", line)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
