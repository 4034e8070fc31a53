"""Requests per second through servotool's RTU path: the embedded simulator (RTU over loopback TCP), `sim serve` on a
socat pty pair, and a libmodbus RTU slave on the same kind of pty pair (the yardstick `sim serve` is held to: at
least 0.8x its rate, issue 30). Then what users run on a clean line: a monitor's samples/s and a backup's duration,
on the embedded simulator and with its line emulated at each profile's baud rate.

Run: python bench/rtu_throughput.py [--requests N] [--rounds R] [--no-users] [--no-slaves] [--against DIR]
Prints the embedded simulator's requests/s; on the ptys, for three masters (servotool as shipped, which listens
3.5 characters after each reply; servotool --silence-ms 0; libmodbus), each slave's requests/s and the sim serve /
libmodbus ratio; then one line per profile with monitor samples/s and backup ms. --against DIR (main's code:
`git archive main | tar -x -C DIR`) prints this checkout's monitor and backup figures beside DIR's, through the
library and through the CLI on --port sim, in interleaved rounds: issue 30 holds them within 10 % of main's on a
clean line. The libmodbus slave is built from bench/modbus_rtu_slave.c with gcc and Debian's libmodbus-dev
(apt-get install libmodbus-dev); without them its line is skipped.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from servotool.connection import ConnectOptions, resolve
from servotool.session import open_drives

HERE = Path(__file__).resolve().parent
BAUD = 115200


def measure(port: str, n: int, profile: str = "dsx7e", baud: int | None = None, silence_ms: float | None = None):
    """(requests/s, ms per request) of n one-register reads (Pn004) through servotool's link."""
    opts = ConnectOptions(
        port=port, profile=profile, baud=baud, timeout=1.0, retries=0, no_identity_check=True, silence_ms=silence_ms
    )
    with open_drives(resolve(opts), notice=lambda _m: None) as (drive,):
        entry = drive.profile.entry("Pn004")
        drive.read_entries([entry])
        t0 = time.perf_counter()
        for _ in range(n):
            drive.read_entries([entry])
        elapsed = time.perf_counter() - t0
    return n / elapsed, elapsed / n * 1000


def measure_libmodbus(port: str, n: int, baud: int) -> tuple[float, float]:
    """(requests/s, ms per request) of n one-register reads of 0x2004 by a libmodbus master (mbpoll's library)."""
    import ctypes
    import ctypes.util

    lib = ctypes.CDLL(ctypes.util.find_library("modbus") or "libmodbus.so.5")
    lib.modbus_new_rtu.restype = ctypes.c_void_p
    lib.modbus_new_rtu.argtypes = [ctypes.c_char_p, ctypes.c_int, ctypes.c_char, ctypes.c_int, ctypes.c_int]
    for name in ("modbus_set_slave", "modbus_connect", "modbus_read_registers", "modbus_close", "modbus_free"):
        getattr(lib, name).argtypes = [ctypes.c_void_p, *([ctypes.c_int] if name == "modbus_set_slave" else [])]
    lib.modbus_read_registers.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int, ctypes.c_void_p]
    ctx = lib.modbus_new_rtu(str(port).encode(), baud, b"N", 8, 1)
    lib.modbus_set_slave(ctx, 1)
    assert lib.modbus_connect(ctx) == 0
    regs = (ctypes.c_uint16 * 1)()
    try:
        t0 = time.perf_counter()
        for _ in range(n):
            if lib.modbus_read_registers(ctx, 0x2004, 1, regs) != 1:
                raise RuntimeError("libmodbus master: no answer")
        elapsed = time.perf_counter() - t0
    finally:
        lib.modbus_close(ctx)
        lib.modbus_free(ctx)
    return n / elapsed, elapsed / n * 1000


@contextmanager
def pty_pair(tmp: Path) -> Iterator[tuple[Path, Path]]:
    """(slave side, master side) of a socat pty pair."""
    a, b = tmp / f"slave{time.monotonic_ns()}", tmp / f"master{time.monotonic_ns()}"
    socat = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"], stderr=subprocess.DEVNULL
    )
    try:
        while not (a.exists() and b.exists()):
            time.sleep(0.02)
        yield a, b
    finally:
        socat.terminate()
        socat.wait()


@contextmanager
def serving(cmd: list[str], ready_on: str) -> Iterator[int]:
    """Run a slave until the block ends, once it has said `ready_on` (stderr for sim serve, stdout for libmodbus);
    its process id."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        stream = proc.stderr if ready_on == "stderr" else proc.stdout
        assert stream is not None
        stream.readline()
        yield proc.pid
    finally:
        proc.terminate()
        proc.wait()


def cpu_s(pid: int) -> float:
    """A process's CPU time so far (user + system, Linux /proc; 0 elsewhere): what a slave spends per request is its
    capacity, whatever else the machine runs."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


def libmodbus_slave(tmp: Path) -> Path | None:
    """bench/modbus_rtu_slave.c built against libmodbus-dev, or None when gcc or libmodbus-dev is missing."""
    if not shutil.which("gcc") or not Path("/usr/include/modbus/modbus.h").exists():
        return None
    exe = tmp / "modbus_rtu_slave"
    flags = subprocess.run(["pkg-config", "--cflags", "--libs", "libmodbus"], capture_output=True, text=True)
    libs = flags.stdout.split() if flags.returncode == 0 else ["-I/usr/include/modbus", "-lmodbus"]
    subprocess.run(["gcc", "-O2", "-o", str(exe), str(HERE / "modbus_rtu_slave.c"), *libs], check=True)
    return exe


MASTERS = {
    "servotool (RTU silence after each reply)": lambda b, n: measure(str(b), n, baud=BAUD),
    "servotool --silence-ms 0": lambda b, n: measure(str(b), n, baud=BAUD, silence_ms=0.0),
    "libmodbus master": lambda b, n: measure_libmodbus(str(b), n, BAUD),
}


def slaves(tmp: Path, n: int, rounds: int) -> None:
    rate, rtt = measure("sim", n)
    print(f"embedded sim (RTU over loopback TCP): {rate:8.0f} requests/s  {rtt:6.3f} ms/request")
    if not shutil.which("socat"):
        print("socat not found: the pty lines are skipped")
        return
    exe = libmodbus_slave(tmp)
    if exe is None:
        print("libmodbus slave: needs gcc and libmodbus-dev (apt-get install libmodbus-dev); sim serve alone")
    serve = [sys.executable, "-m", "servotool", "sim", "serve", "--baud", str(BAUD), "--port"]
    with ExitStack() as stack:
        lines = {}  # slave -> (the master's end of its pty pair, the slave's pid), both serving throughout
        for slave in ("sim serve", "libmodbus slave") if exe else ("sim serve",):
            a, b = stack.enter_context(pty_pair(tmp))
            cmd = [*serve, str(a)] if slave == "sim serve" else [str(exe), str(a), str(BAUD)]
            lines[slave] = (b, stack.enter_context(serving(cmd, "stderr" if slave == "sim serve" else "stdout")))
        print(
            f"over a socat pty at {BAUD} baud: requests/s, best and median of {rounds} interleaved rounds, and the "
            f"slave's CPU time per request (its capacity, however loaded the machine is)"
        )
        for master, run in MASTERS.items():
            rates: dict[str, list[float]] = {slave: [] for slave in lines}
            cpu = dict.fromkeys(lines, 0.0)
            for _ in range(rounds):
                for slave, (b, pid) in lines.items():
                    c0 = cpu_s(pid)
                    rates[slave].append(run(b, n)[0])
                    cpu[slave] += cpu_s(pid) - c0
            for slave, got in rates.items():
                us = cpu[slave] / (rounds * n) * 1e6
                print(f"  {master:<42} {slave:<16} {max(got):8.0f} {statistics.median(got):8.0f} {us:6.0f} us")
            if len(rates) == 2:
                best = max(rates["sim serve"]) / max(rates["libmodbus slave"])
                ratio = statistics.median(
                    a / b for a, b in zip(rates["sim serve"], rates["libmodbus slave"], strict=True)
                )
                print(f"  {master:<42} sim serve / libmodbus slave: {best:.2f} best, {ratio:.2f} median of the rounds")
        # A pty carries bytes at memory speed; a real line at BAUD carries a one-register read's 8 + 7 bytes and
        # the two 3.5-character silences in 22 characters of 10 bits.
        ceiling = BAUD / (22 * 10)
        print(f"  a real {BAUD}-baud line carries at most {ceiling:.0f} such requests/s (22 characters each)")


def users(samples: int, show: bool = True) -> dict[str, list[float]]:
    """A monitor's samples/s and a backup's duration per profile, through the library (no CLI start-up): on
    loopback with no line emulated, and with the line emulated at the profile's factory speed. By "profile line":
    [monitor samples/s, requests per sample, backup ms, backup requests]."""
    from servotool.drive import Drive
    from servotool.link.master import RtuMaster
    from servotool.link.ports import LinkSettings
    from servotool.model.loader import load_profile
    from servotool.ops import backup, monitor
    from servotool.sim.firmware import build_drive
    from servotool.sim.server import EmbeddedSim

    if show:
        print(
            f"{'profile':<8} {'line':>14} {'monitor/s':>10} {'requests/sample':>16} {'backup ms':>10} {'requests':>9}"
        )
    figures: dict[str, list[float]] = {}
    for profile_id in ("sd25", "is620p", "sdc", "dsx7e"):
        profile = load_profile(profile_id)
        for baud in (0, profile.line.baud):
            sim_drive = build_drive(profile, profile.default_unit, persist=False)
            sim_drive.settings["line_baud"] = "factory" if baud else "fast"
            sim = EmbeddedSim([sim_drive], line=profile.line)
            link = RtuMaster(LinkSettings(sim.port, profile.line, timeout=1.0, retries=2))
            try:
                drive = Drive(link, profile, profile.default_unit)
                entries = monitor.default_entries(profile)
                drive.read_entries(entries)
                count = samples if not baud else max(10, samples * baud // 115200 // 4)
                r0, t0 = link.requests, time.perf_counter()
                for _ in range(count):
                    drive.read_entries(entries)
                rate, per = count / (time.perf_counter() - t0), (link.requests - r0) / count
                r0, t0 = link.requests, time.perf_counter()
                backup.take(drive)
                took, asked = (time.perf_counter() - t0) * 1000, link.requests - r0
            finally:
                link.close()
                sim.close()
            where = f"{baud} baud" if baud else "loopback"
            figures[f"{profile_id} {where}"] = [rate, per, took, asked]
            if show:
                print(f"{profile_id:<8} {where:>14} {rate:>10.1f} {per:>16.2f} {took:>10.0f} {asked:>9}")
    return figures


def cli_users(duration: float) -> dict[str, list[float]]:
    """What users run, through the CLI on `--port sim` (its line emulated at the profile's factory speed, as by
    default; SD25's line raised for the backup, as by default): by profile, [monitor samples/s over `duration` s,
    backup s, start-up included]."""
    import re

    figures: dict[str, list[float]] = {}
    tmp = Path(tempfile.mkdtemp())
    env = {**os.environ, "SERVOTOOL_SIM_DIR": str(tmp / "sim"), "SERVOTOOL_BACKUP_DIR": str(tmp / "bk")}
    for profile_id in ("sd25", "is620p", "sdc", "dsx7e"):
        base = [sys.executable, "-m", "servotool", "--port", "sim", "--profile", profile_id]
        mon = subprocess.run(
            [*base, "monitor", "--rate", "1000", "--duration", str(duration), "--json"],
            capture_output=True,
            text=True,
            env=env,
            check=True,
        )
        found = re.search(r"(\d+) samples in ([\d.]+) s", mon.stderr + mon.stdout)
        rate = int(found.group(1)) / float(found.group(2)) if found else float("nan")
        t0 = time.perf_counter()
        subprocess.run(
            [*base, "param", "backup", "-o", str(tmp / f"{profile_id}.yaml"), "--force"],
            capture_output=True,
            env=env,
            check=True,
        )
        figures[profile_id] = [rate, time.perf_counter() - t0]
    return figures


def against(tree: str, rounds: int, samples: int, duration: float) -> None:
    """This checkout's monitor and backup figures beside another tree's (`git archive main | tar -x -C DIR`), in
    interleaved rounds (the machine's load moves between them), the median of each, and this/that."""
    here = str(HERE.parent)

    def run(root: str, mode: str) -> dict[str, list[float]]:
        env = {**os.environ, "PYTHONPATH": root}
        args = [sys.executable, str(HERE / "rtu_throughput.py"), mode, "--samples", str(samples)]
        out = subprocess.run([*args, "--duration", str(duration)], capture_output=True, text=True, env=env, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    for mode, heads in (
        ("--lib-json", ("monitor/s", "req/sample", "backup ms", "requests")),
        ("--cli-json", ("monitor/s", "backup s")),
    ):
        got: dict[str, list[dict[str, list[float]]]] = {here: [], tree: []}
        for _ in range(rounds):
            for root in (here, tree):
                got[root].append(run(root, mode))
        what = "library, no CLI start-up" if mode == "--lib-json" else "CLI on --port sim, start-up included"
        print(f"{what}: median of {rounds} interleaved rounds, this checkout | {tree} | this/that")
        for key in got[here][0]:
            cells = []
            for i, head in enumerate(heads):
                a = statistics.median(r[key][i] for r in got[here])
                b = statistics.median(r[key][i] for r in got[tree])
                cells.append(f"{head} {a:8.1f} | {b:8.1f} | {a / b if b else float('nan'):5.2f}")
            print(f"  {key:<16} " + "   ".join(cells))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--requests", type=int, default=1000)
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds of each master and slave on the ptys")
    ap.add_argument("--no-users", action="store_true", help="only the request rates")
    ap.add_argument("--no-slaves", action="store_true", help="only the monitor and backup figures")
    ap.add_argument("--against", metavar="DIR", help="compare monitor and backup with another tree's code (main's)")
    ap.add_argument("--samples", type=int, default=200, help="monitor samples on loopback (fewer at line speed)")
    ap.add_argument("--duration", type=float, default=3.0, help="seconds of each CLI monitor run (--against)")
    ap.add_argument("--lib-json", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cli-json", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp())
    os.environ.setdefault("SERVOTOOL_SIM_DIR", str(tmp / "sim"))
    if args.lib_json or args.cli_json:
        print(json.dumps(users(args.samples, show=False) if args.lib_json else cli_users(args.duration)))
        return
    print(f"load average: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    if not args.no_slaves:
        slaves(tmp, args.requests, args.rounds)
    if args.against:
        against(args.against, args.rounds, args.samples, args.duration)
    elif not args.no_users:
        users(args.samples)
    print(f"load average: {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")


if __name__ == "__main__":
    main()
