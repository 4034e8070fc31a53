"""The host's journal after kill -9 (issue 30 item 6): one record per bus (resolved, whatever its spelling), profile
and unit; found again after a replug under another name. Stored values are judged by pymodbus or the simulated
drive's own state file, not by servotool's recovery."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.ops.plain_client import read_registers

ROOT = Path(__file__).resolve().parents[2]
PO505 = 505  # SD25's EEPROM switch: d 1 1 (0x0101) keeps Modbus writes in RAM, d 1 0 stores them
RAM_ONLY = 0x0101
needs_socat = pytest.mark.skipif(not shutil.which("socat"), reason="needs socat (installed by .ci/run)")


def kill_after_reply(args: list[str], request: str) -> None:
    """Run servotool -v ARGS and kill -9 it as soon as the drive has answered the request whose frame starts with
    `request` (hex, as -v prints it): the switch is changed on the drive and the command dies with it changed."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "-v", *args],
        cwd=ROOT,
        env=dict(os.environ),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stderr is not None
    sent = False
    for line in proc.stderr:
        if line.startswith(f">> {request}"):
            sent = True
        elif sent and line.startswith("<< "):
            os.kill(proc.pid, signal.SIGKILL)
            break
    proc.wait(30)
    assert proc.returncode == -signal.SIGKILL, f"the command ended by itself ({proc.returncode})"


def state(profile: str, *codes: str) -> dict[str, tuple[int, int]]:
    """code -> (RAM, EEPROM) from the simulated drive's own state file."""
    from servotool.files import sim_state_dir

    data = json.loads((sim_state_dir() / f"{profile}-unit1.json").read_text())
    return {c: (data["ram"][c], data["eeprom"][c]) for c in codes}


def test_a_record_left_through_one_spelling_of_a_tcp_port_is_finished_through_another(cli, serve):
    """kill -9 through tcp://127.0.0.1:P with the switch on EEPROM; the next command through tcp://localhost:P put
    nothing back and stored a plain set in EEPROM. Now both names are one bus."""
    port = serve("sd25")
    number = port.rpartition(":")[2]
    kill_after_reply(["--port", port, "-P", "sd25", "param", "set", "--save", "Po003=21", "Po101=30"], "01 06 01 f9")
    assert read_registers(port, PO505) == [0x0100]  # left storing every write
    r = cli("--port", f"tcp://localhost:{number}", "-P", "sd25", "param", "set", "Po110=34")
    assert r.code == 0 and "put Po505 back to d 1 1 (was d 1 0)" in r.err, r.err
    assert "not saved to EEPROM" in r.err
    assert read_registers(port, PO505) == [RAM_ONLY]
    assert state("sd25", "Po110")["Po110"] == (34, 200)  # in RAM only, as the warning says


@needs_socat
def test_a_replugged_adapter_under_another_name_still_finishes_the_recovery(cli, serve, tmp_path):
    """The adapter the dead process used is gone and the drive answers on another device name: its record is
    found by the drive's profile, unit and identity, and finished there."""

    def pty_pair(name: str) -> tuple[subprocess.Popen[bytes], Path, Path]:
        a, b = tmp_path / f"{name}-drive", tmp_path / f"{name}-host"
        socat = subprocess.Popen(["socat", f"pty,raw,echo=0,link={a}", f"pty,raw,echo=0,link={b}"])
        end = time.monotonic() + 5
        while not (a.exists() and b.exists()) and time.monotonic() < end:
            time.sleep(0.02)
        return socat, a, b

    def served_on(device: Path) -> subprocess.Popen[str]:
        server = subprocess.Popen(
            [sys.executable, "-m", "servotool", "sim", "serve", "-P", "sd25", "--parity", "N", "--port", str(device)],
            cwd=ROOT,
            env=dict(os.environ),
            stderr=subprocess.PIPE,
            text=True,
        )
        assert server.stderr is not None and "serving on" in server.stderr.readline()
        return server

    first, drive_end, host_end = pty_pair("first")
    server = served_on(drive_end)
    old = os.path.realpath(host_end)
    args = ["--port", str(host_end), "--parity", "N", "-P", "sd25"]
    kill_after_reply([*args, "param", "set", "--save", "Po003=21", "Po101=30"], "01 06 01 f9")
    assert state("sd25", "Po505")["Po505"][0] == 0x0100
    second, drive_end, host_end = pty_pair("second")  # plugged in before the first goes: a name of its own
    server.terminate()
    server.wait(10)
    first.terminate()
    first.wait(10)
    server = served_on(drive_end)
    try:
        assert os.path.realpath(host_end) != old and not os.path.exists(old)
        r = cli("--port", str(host_end), "--parity", "N", "-P", "sd25", "param", "get", "Po505", "--json")
        assert r.code == 0, r.err
        assert f"through {old}, which is no longer there" in r.err, r.err
        assert "put Po505 back to d 1 1 (was d 1 0)" in r.err
        assert state("sd25", "Po505")["Po505"] == (RAM_ONLY, RAM_ONLY)
        from servotool.ops.journal import journal_dir

        assert not list(journal_dir().glob("*.json"))
    finally:
        server.terminate()
        server.wait(10)
        second.terminate()
        second.wait(10)


def test_a_record_is_read_only_by_its_own_profile_under_port_sim(cli, sim_dir):
    """A DSX7E JOG's record was dropped as 'damaged' by an IS620P command on --port sim, leaving Pn512 changed:
    each profile's simulated drive has its own record, finished by a command on that drive."""
    from servotool.connection import ConnectOptions, resolve
    from servotool.ops import journal
    from servotool.session import open_drives

    with open_drives(resolve(ConnectOptions(port="sim", profile="dsx7e")), notice=lambda _m: None) as (d,):
        jog_speed = d.profile.entry("Pn512")
        original = d.read_entries([jog_speed])[0].raw
        journal.note_settings(d, {"Pn512": original})  # as a JOG does before it writes its speed
        d.write_verified(jog_speed, original + 50)
        record = journal.record_path(d)
    r = cli("--port", "sim", "-P", "is620p", "param", "get", "H08-00")
    assert r.code == 0 and "journal" not in r.err and "damaged" not in r.err, r.err
    assert record.exists()
    r = cli("--port", "sim", "-P", "dsx7e", "param", "get", "Pn512", "--json")
    assert r.code == 0 and f"put Pn512 to {original}" in r.err, r.err
    assert state("dsx7e", "Pn512")["Pn512"][0] == original
    assert not record.exists()


def test_a_record_of_another_profile_on_the_same_port_is_named_not_dropped(cli, serve):
    """On a real bus the record of a drive addressed with another --profile is left for that profile, and said."""
    from servotool.model.loader import load_profile
    from servotool.ops import journal

    port = serve("sd25")

    class Other:  # what names a record: its bus, profile and unit
        unit, profile = 1, load_profile("is620p")

    other = Other()
    other.port = f"tcp://localhost:{port.rpartition(':')[2]}"  # type: ignore[attr-defined]
    path = journal.record_path(other)  # type: ignore[arg-type]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        json.dumps(
            {
                "switch": {"code": "H0C-13", "original": 1},
                "pid": 1,
                "port": other.port,
                "bus": other.port,
                "unit": 1,
                "profile": "is620p",
                "identity": {},
            }
        )
    )
    r = cli("--port", port, "-P", "sd25", "param", "get", "Po505")
    assert r.code == 0 and "using profile is620p ended with unit 1 of this port changed" in r.err, r.err
    assert path.exists()


def test_a_param_set_killed_between_writes_is_named_value_by_value_by_the_next_command(cli, serve):
    """kill -9 between the writes of one param set left some values written (6 of 12) and the next command named
    only the switch: the set is journaled before its first write, and the next command reads each value back."""
    from servotool.ops.journal import journal_dir

    port = serve("sd25", "--response-delay", "40")
    wanted = {"Po003": (3, 21, "21", "16"), "Po101": (101, 300, "30.0", "60.0"), "Po110": (110, 50, "50", "200")}
    wanted["Po200"] = (200, 500, "500", "1000")  # code: address, raw, as set, as before; four separate writes
    args = ["--port", port, "-P", "sd25", "param", "set", *(f"{c}={v[2]}" for c, v in wanted.items())]
    kill_after_reply(args, "01 06 00 65")  # Po101 (address 0x65) written: Po110 and Po200 are not
    assert list(journal_dir().glob("*.json")), "no record of the set was left"
    landed = {c: read_registers(port, v[0]) == [v[1]] for c, v in wanted.items()}
    assert landed["Po003"] and landed["Po101"] and not landed["Po200"], landed
    r = cli("--port", port, "-P", "sd25", "param", "get", "Po505")
    assert r.code == 0, r.err
    line = next(x for x in r.err.splitlines() if "a param set (pid" in x)
    wrote, _, rest = line.partition("not written:")
    for code, (_address, _raw, new, old) in wanted.items():
        if landed[code]:
            assert f"{code} = {new} (was {old})" in wrote, line
        else:
            assert f"{code} (still {old})" in rest, line
    assert line.endswith("run it again to finish")
    assert not list(journal_dir().glob("*.json"))


@pytest.mark.parametrize(
    ("old_bus", "identity", "adopted"),
    [
        ("ttyUSB0", None, True),  # gone, same drive: finished here
        ("/dev/serial/by-id/usb-FTDI_FT232R_A1-if00-port0", None, False),  # that adapter would come back by name
        ("ttyUSB0", {"So-00": 101, "So-46": 100}, False),  # another firmware: another drive
    ],
)
def test_a_record_under_a_gone_device_is_taken_up_only_by_the_same_drive(sim_dir, tmp_path, old_bus, identity, adopted):
    from servotool.clock import VirtualClock
    from servotool.drive import Drive
    from servotool.model.loader import load_profile
    from servotool.ops import journal
    from servotool.sim.firmware import build_drive
    from servotool.sim.virtual import VirtualLink

    profile = load_profile("sd25")
    clock = VirtualClock()
    sim = build_drive(profile, 1, clock, persist=False)
    link = VirtualLink([sim], clock)
    bus = old_bus if old_bus.startswith("/dev/") else str(tmp_path / old_bus)  # never existing
    old = Drive(link, profile, 1, port=bus)
    journal.note_switch(old, "Po505", 0x0101)
    if identity is not None:
        record = json.loads(journal.record_path(old).read_text())
        journal.record_path(old).write_text(json.dumps({**record, "identity": identity}))
    old.write_raw(profile.entry("Po505"), 0x0100)  # and then the process died
    new = Drive(link, profile, 1, port=str(tmp_path / "ttyUSB1"))
    lines: list[str] = []
    with journal.port_lock(new, notice=lines.append):
        pass
    assert (sim.bank.ram["Po505"] == 0x0101) is adopted, lines
    assert journal.record_path(old).exists() is not adopted
    if adopted:
        assert f"through {bus}, which is no longer there" in lines[0] and "put Po505 back" in lines[1]
    else:
        assert lines == []
