"""Several machines for the fleet and Ansible tests: a `sim serve` process each, with its own simulated drives
(state folder), on a free loopback port; faults injected into one machine's drives through its state folder."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from servotool.model.loader import load_profile
from servotool.sim.device import SimulatedDrive

ROOT = Path(__file__).resolve().parent.parent


@dataclass
class Machine:
    """One simulated machine: its bus (tcp:// port), its drives' state folder and its server process."""

    name: str
    port: str
    sim_dir: Path
    proc: subprocess.Popen[str]

    def inject_fault(self, profile: str, unit: int, code: str) -> None:
        """Make writes to one entry of one drive fail with exception 03 (the running server reloads the state)."""
        before = os.environ.get("SERVOTOOL_SIM_DIR")
        os.environ["SERVOTOOL_SIM_DIR"] = str(self.sim_dir)
        try:
            SimulatedDrive(load_profile(profile), unit).inject_fault(code)
        finally:
            if before is None:
                os.environ.pop("SERVOTOOL_SIM_DIR", None)
            else:
                os.environ["SERVOTOOL_SIM_DIR"] = before


def start(name: str, folder: Path, profile: str, units: list[int], *more: str) -> Machine:
    """`sim serve` for one machine, its drives in folder/NAME (it prints the port it bound first)."""
    sim_dir = folder / name
    args = [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0", "-P", profile, *more]
    for u in units:
        args += ["--unit", str(u)]
    proc = subprocess.Popen(
        args,
        cwd=ROOT,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "SERVOTOOL_SIM_DIR": str(sim_dir)},
    )
    banner = proc.stderr.readline() if proc.stderr else ""
    found = re.search(r"serving on (tcp://127\.0\.0\.1:\d+)", banner)
    assert found, banner
    return Machine(name, found.group(1), sim_dir, proc)


def stop(machines: list[Machine]) -> None:
    for m in machines:
        m.proc.send_signal(signal.SIGINT)
    for m in machines:
        try:
            m.proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            m.proc.kill()
            m.proc.communicate()
