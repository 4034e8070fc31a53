"""Does a kill -9 ever leave a drive's settings unaccounted for? `param restore`, `param reset`, `param set --save`
and `run PLAN` are killed at random points on simulated SD25 and IS620P drives behind a slow line (`sim config
--line-baud`); then the next servotool command runs on the drive, and the drive is checked against what the journal
and the automatic backup say:

- the EEPROM switch (SD25 Po505, IS620P H0C-13, in RAM and EEPROM) is as it was before the killed command (a
  factory reset may also leave it at its default, which is what a reset does);
- every parameter is either as before or as the killed command was setting it (a reset: the factory default);
- when the next command reports an interrupted restore, the number of entries it says differ from the automatic
  backup is the true number;
- no journal record and no temporary file is left in servotool's folders (automatic backups, journal, simulator).

Half the kills come at any moment of the command, half within --window s of its first write (the journal record
appearing, or a reset's automatic backup), where a kill can leave the switch changed or a restore half done.

Run: python bench/kill_storm.py [--kills N] [--seed S] [--baud B] [--window S] [--ops restore,reset,save,plan]
Prints, per profile and operation, kills, recovered and % (the target is 100 %), and how many of the kills left
something the next command put back or reported (the switch changed, a restore midway).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROFILES = {
    # profile: (switch code, its raw value meaning RAM only, values the target backup has, values set with --save)
    "sd25": (
        "Po505",
        0x0101,
        {"Po101": "75", "Po102": "35", "Po109": "11", "Po110": "12", "Po111": "13", "Po301": "50"},
        {"Po101": "66", "Po102": "44", "Po109": "21"},
    ),
    "is620p": (
        "H0C-13",
        0,
        {"H08-00": "30.0", "H08-02": "50.0", "H06-03": "150", "H06-05": "60"},
        {"H08-00": "33.0", "H08-02": "55.0", "H06-05": "70"},
    ),
}
OPS = ("restore", "reset", "save", "plan")


def load_profile_cached(name: str):
    from servotool.model.loader import load_profile

    return load_profile(name)


class Storm:
    """One profile's simulated drive in its own folders, brought to a known state before every kill."""

    def __init__(self, profile: str, baud: int, root: Path) -> None:
        self.profile, self.root = profile, root
        self.switch, self.ram_mode, self.target_values, self.save_values = PROFILES[profile]
        self.env = {
            **os.environ,
            "SERVOTOOL_SIM_DIR": str(root / "sim"),
            "SERVOTOOL_BACKUP_DIR": str(root / "auto"),
            "SERVOTOOL_CONFIG": str(root / "none.yaml"),
            "PYTHONPATH": str(ROOT),
            "COLUMNS": "200",
        }
        for var in ("SERVOTOOL_PORT", "SERVOTOOL_PROFILE", "SERVOTOOL_UNIT"):
            self.env.pop(var, None)
        self.state_file = root / "sim" / f"{profile}-unit1.json"
        self.target = root / "work" / "target.yaml"
        self.plan = root / "work" / "plan.yaml"
        self.repaired = 0  # kills after which the next command had something to put back or report
        (root / "work").mkdir(parents=True)
        self._prepare(baud)

    def cli(self, *args: str, timeout: float = 300) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "servotool", *args],
            capture_output=True,
            text=True,
            env=self.env,
            cwd=ROOT,
            timeout=timeout,
        )

    def on_drive(self, *args: str) -> subprocess.CompletedProcess[str]:
        return self.cli("--port", "sim", "-P", self.profile, *args)

    def _prepare(self, baud: int) -> None:
        """In-process (through the library, as the CLI would): a target backup, then a drive that differs from it
        with its switch on RAM only and one value already in RAM, on a slow line."""
        from servotool.connection import ConnectOptions, resolve
        from servotool.ops import backup, params, restore
        from servotool.session import open_drives
        from servotool.sim import state as sim_state

        saved = {k: os.environ.get(k) for k in ("SERVOTOOL_SIM_DIR", "SERVOTOOL_BACKUP_DIR", "SERVOTOOL_CONFIG")}
        os.environ.update({k: self.env[k] for k in saved})
        try:
            with open_drives(resolve(ConnectOptions(port="sim", profile=self.profile)), notice=lambda _m: None) as (d,):

                def put(values: dict[str, str], save: bool | None, raw: bool = False) -> None:
                    plan = params.prepare_set(d, [f"{k}={v}" for k, v in values.items()], raw=raw)
                    params.set_values(d, plan, save)

                put(self.target_values, True)
                backup.write_backup(d, self.target)
                restore.factory_reset(d)
                put({self.switch: str(self.ram_mode)}, None, raw=True)  # RAM only: the switch flips
                put(dict(list(self.save_values.items())[:1]), None)  # one value already in RAM
            sim_state.configure(load_profile_cached(self.profile), 1, line_baud=baud)
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        steps = "\n".join(
            f"  - {line}"
            for line in (
                "set: {" + ", ".join(f"{k}: {v}" for k, v in self.save_values.items()) + "}",
                "save:",
                "backup: {file: out.yaml, overwrite: true}",
            )
        )
        self.plan.write_text(f"port: sim\nprofile: {self.profile}\nsteps:\n{steps}\n")
        self.start_state = self.state_file.read_text()
        self.before = self.drive_state()

    def drive_state(self) -> dict[str, dict[str, int]]:
        data = json.loads(self.state_file.read_text())
        return {"ram": data["ram"], "eeprom": data["eeprom"]}

    def command(self, op: str) -> list[str]:
        if op == "restore":
            return ["--port", "sim", "-P", self.profile, "param", "restore", str(self.target), "--yes"]
        if op == "reset":
            return ["--port", "sim", "-P", self.profile, "param", "reset", "--yes"]
        if op == "save":
            return [
                "--port",
                "sim",
                "-P",
                self.profile,
                "param",
                "set",
                "--save",
                *(f"{k}={v}" for k, v in self.save_values.items()),
            ]
        return ["run", str(self.plan), "--yes"]

    def reset(self) -> None:
        """Back to the known state: the drive's state file as prepared, no automatic backups or journal."""
        self.state_file.write_text(self.start_state)
        shutil.rmtree(self.root / "auto", ignore_errors=True)
        for f in (self.root / "work").glob("*"):
            if f.name not in ("target.yaml", "plan.yaml"):
                f.unlink()

    def duration(self, op: str) -> float:
        self.reset()
        t0 = time.monotonic()
        r = self.cli(*self.command(op))
        assert r.returncode == 0, f"{op}: {r.stderr}"
        return time.monotonic() - t0

    def marker(self, op: str) -> bool:
        """The operation has reached its writes: a journal record (switch or restore), or a reset's backup."""
        if op == "reset":
            return any((self.root / "auto").glob("*before-reset.yaml"))
        return any((self.root / "auto" / "journal").glob("*.json"))

    def kill_at(self, op: str, delay: float, targeted: bool = False) -> tuple[bool, str]:
        """Kill the operation after delay s (targeted: delay s after it reached its writes); run the next
        command; (recovered, why not)."""
        self.reset()
        proc = subprocess.Popen(
            [sys.executable, "-m", "servotool", *self.command(op)],
            env=self.env,
            cwd=ROOT,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        if targeted:
            while proc.poll() is None and not self.marker(op):
                time.sleep(0.002)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        nxt = self.on_drive("param", "get", self.switch, "--json")
        if nxt.returncode != 0:
            return False, f"next command failed: {nxt.stderr.strip()}"
        good, why = self.check(op, nxt.stderr)
        self.repaired += good and ("servotool: put " in nxt.stderr or "was interrupted" in nxt.stderr)
        return good, why

    def allowed(self, op: str) -> dict[str, set[int]]:
        """code -> raw values a parameter may have after the killed op."""
        from servotool.model.loader import load_profile

        prof = load_profile(self.profile)
        ok = {c: {v} for c, v in self.before["ram"].items()}
        if op == "reset":
            for e in prof.of_class("Pn"):
                if e.default is not None and e.code in ok:
                    ok[e.code].add(e.default)
        elif op == "restore":
            import yaml

            for c, v in yaml.safe_load(self.target.read_text())["values"].items():
                if c != self.switch and c in ok:
                    ok[c].add(v)
        else:
            from servotool.model.codec import parse_value

            for c, v in self.save_values.items():
                ok[c].add(parse_value(prof.entry(c), v))
        return ok

    def check(self, op: str, said: str) -> tuple[bool, str]:
        now = self.drive_state()
        switch_ok = {self.before["ram"][self.switch]}
        if op == "reset":
            from servotool.model.loader import load_profile

            switch_ok.add(load_profile(self.profile).entry(self.switch).default)
        if now["ram"][self.switch] not in switch_ok or now["eeprom"][self.switch] not in switch_ok:
            return False, f"switch {self.switch} left at {now['ram'][self.switch]}"
        allowed = self.allowed(op)
        bad = [c for c, v in now["ram"].items() if c in allowed and v not in allowed[c]]
        if bad:
            return False, f"unexpected values: {bad[:4]}"
        m = re.search(r"differs from the automatic backup (\S+) in (\d+)", said)
        if m:
            import yaml

            auto = yaml.safe_load(Path(m.group(1)).read_text())["values"]
            true = sum(1 for c, v in auto.items() if c != self.switch and now["ram"].get(c) != v)
            if true != int(m.group(2)):
                return False, f"said {m.group(2)} entries differ, truly {true}"
        journal = list((self.root / "auto" / "journal").glob("*.json")) if (self.root / "auto").exists() else []
        if journal:
            return False, f"journal record left: {journal[0].name}"
        tmps = [p for d in ("sim", "auto") for p in (self.root / d).rglob("*.tmp")]
        if tmps:
            return False, f"temporary file left: {tmps[0]}"
        return True, ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=10, help="kills per profile and operation")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--baud", type=int, default=2400, help="the emulated line's baud (slower: more to kill)")
    ap.add_argument("--window", type=float, default=1.0, help="targeted kills: within this many s of the writes")
    ap.add_argument("--ops", default=",".join(OPS))
    ap.add_argument("--profiles", default=",".join(PROFILES))
    args = ap.parse_args()
    rng = random.Random(args.seed)
    totals: Counter[str] = Counter()
    print(f"{'profile':8} {'op':8} {'kills':>5} {'recovered':>9} {'%':>6} {'repaired':>8}  (line {args.baud} Bd)")
    for profile in args.profiles.split(","):
        with tempfile.TemporaryDirectory(prefix="kill-storm-") as tmp:
            storm = Storm(profile, args.baud, Path(tmp))
            for op in args.ops.split(","):
                span = storm.duration(op)
                ok, storm.repaired = 0, 0
                for n in range(args.kills):
                    # half at any moment of the command, half in the window where it writes
                    targeted = n % 2 == 1
                    good, why = storm.kill_at(
                        op, rng.uniform(0, args.window) if targeted else rng.uniform(0.2, span), targeted
                    )
                    ok += good
                    if not good:
                        print(f"  {profile} {op}: NOT recovered: {why}", file=sys.stderr)
                totals["kills"] += args.kills
                totals["ok"] += ok
                print(
                    f"{profile:8} {op:8} {args.kills:5d} {ok:9d} {100 * ok / args.kills:6.1f} {storm.repaired:8d}  "
                    f"(uninterrupted {span:.1f} s)",
                    flush=True,
                )
    share = 100 * totals["ok"] / max(1, totals["kills"])
    print(f"{'all':8} {'':8} {totals['kills']:5d} {totals['ok']:9d} {share:6.1f}")


if __name__ == "__main__":
    main()
