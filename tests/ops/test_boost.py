"""A raised line for long exchanges (issue 31 item 1): SD25's Po504 written in RAM only for the duration, the master
following it and proving it, the factory line back on every way out, and a line a killed process (or a line that
went dead) left raised found at either speed and put back. Stored values are judged with pymodbus' own client
against `sim serve`, or from the simulated drive's own state, never through servotool's reads."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time

import pytest

from servotool.connection import ConnectOptions, resolve
from servotool.drive import Drive
from servotool.errors import DeviceError
from servotool.model.loader import load_profile
from servotool.model.schema import parse_profile
from servotool.ops import boost, journal
from servotool.session import Bus
from servotool.sim.faults import LineFaults
from tests.conftest import ROOT
from tests.ops.plain_client import read_registers

PO504 = 504  # SD25: Po n -> address n
FACTORY, RAISED = 2, 5  # Po504 codes: 9600 and 57600 baud


def _ram_value(sim_dir, code: str) -> int:
    """The simulated drive's RAM value of an entry, from its state file (not over the line)."""
    path = sim_dir / "sd25-unit1.json"
    return int(json.loads(path.read_text())["ram"][code])


def test_a_backup_runs_on_a_raised_line_and_leaves_the_factory_line(cli, serve):
    port = serve("sd25")
    r = cli("--port", port, "-P", "sd25", "-v", "param", "backup", "-o", "/dev/null", "--force", "--format", "csv")
    assert r.code == 0, r.err
    assert "line raised to 57600 baud for the backup" in r.err
    frames = re.findall(r">> (01 (?:06|10) 01 f8 [0-9a-f ]+)", r.err)  # writes to 504 (0x01F8)
    assert [f.split()[5] for f in frames] == ["05", "02"], frames  # raised, then put back
    assert read_registers(port, PO504) == [FACTORY]  # pymodbus' own read: the factory code again


def test_the_backup_records_the_line_the_drive_keeps(cli, serve, tmp_path):
    port = serve("sd25")
    out = tmp_path / "b.yaml"
    assert cli("--port", port, "-P", "sd25", "param", "backup", "-o", str(out)).code == 0
    assert re.search(r"^\s+Po504: 2$", out.read_text(), re.M), out.read_text()


def test_another_device_on_the_bus_keeps_the_factory_line_unless_asked(cli, serve):
    port = serve("sd25", "-u", "1", "-u", "3")
    r = cli("--port", port, "-P", "sd25", "-v", "param", "backup", "-o", "/dev/null", "--force", "--format", "csv")
    assert r.code == 0, r.err
    assert "line not raised: unit 3 also answers on this bus" in r.err
    assert not re.search(r">> 01 06 01 f8", r.err)  # Po504 never written
    r = cli("--port", port, "-P", "sd25", "--boost", "-v", "param", "backup", "-o", "/dev/null", "--force")
    assert r.code == 0 and "line raised to 57600 baud" in r.err, r.err
    assert read_registers(port, PO504) == [FACTORY]


def test_no_boost_and_the_config_key_keep_the_factory_line(cli, serve, tmp_path):
    port = serve("sd25")
    r = cli("--port", port, "-P", "sd25", "--no-boost", "-v", "param", "backup", "-o", "/dev/null", "--force")
    assert r.code == 0 and "raised" not in r.err and not re.search(r">> 01 06 01 f8", r.err), r.err
    config = tmp_path / "config.yaml"
    config.write_text("boost: false\n")
    r = cli("--port", port, "-P", "sd25", "-v", "param", "backup", "-o", "/dev/null", "--force",
            env={"SERVOTOOL_CONFIG": str(config)})  # fmt: skip
    assert r.code == 0 and not re.search(r">> 01 06 01 f8", r.err), r.err


def test_a_killed_trace_leaves_a_raised_line_the_next_command_puts_back(cli, sim_dir, tmp_path):
    """--port sim's drive hears only its own speed: at 57600 the factory-line master gets silence, so the next
    command finds the record, talks at the raised speed and puts Po504 back."""
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "servotool",
            "--port",
            "sim",
            "-P",
            "sd25",
            "trace",
            "-d",
            "60",
            "-o",
            str(tmp_path / "t.csv"),
        ],
        cwd=ROOT,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert proc.stderr is not None
        deadline = time.monotonic() + 60
        while "trace armed" not in (line := proc.stderr.readline()) and time.monotonic() < deadline:
            assert line, "the trace ended early"
        assert _ram_value(sim_dir, "Po504") == RAISED
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po001", "--json")
    assert r.code == 0, r.err
    assert f"(pid {proc.pid}) ended with the line of unit 1 raised to 57600 baud; put Po504 back" in r.err
    assert _ram_value(sim_dir, "Po504") == FACTORY
    r = cli("--port", "sim", "-P", "sd25", "param", "get", "Po001")
    assert r.code == 0 and "raised" not in r.err, r.err  # the record is gone


@pytest.fixture
def bus(sim_dir):
    """An --port sim bus to an SD25 whose line can go bad (sim.proxy), and a second one opened later (the next
    command)."""
    opened: list[Bus] = []

    def open_bus(faults: LineFaults | None = None) -> Bus:
        res = resolve(ConnectOptions(port="sim", profile="sd25"))
        b = Bus(res, notice=lambda _line: None)
        if faults is not None:  # the same drives behind a line that can go bad
            b.close()
            from servotool.sim.firmware import build_drive
            from servotool.sim.server import EmbeddedSim

            b.sim = EmbeddedSim([build_drive(res.profile, 1)], faults, line=res.settings.line)
            from servotool.link.master import RtuMaster
            from servotool.link.ports import LinkSettings

            b.link = RtuMaster(LinkSettings(b.sim.port, res.settings.line, timeout=0.3, retries=1))
            b.link.line_listeners.append(b.sim.host_speaks)
        opened.append(b)
        return b

    yield open_bus
    for b in opened:
        b.close()


def test_a_line_that_cannot_carry_the_speed_falls_back_at_once(bus, sim_dir):
    b = bus(LineFaults())
    [d] = b.drives()
    assert b.sim is not None and b.sim.proxy is not None
    b.sim.proxy.set_faults(LineFaults({"crc": 0.3}, seed=3))  # a line that garbles: the trial must fail
    said: list[str] = []
    with boost.line_boost([d], None, sole=True, notice=said.append) as facts:
        assert not facts.raised and facts.baud == 9600
        b.sim.proxy.set_faults(LineFaults())
        assert d.read_entries([d.profile.entry("Po504")])[0].raw == FACTORY
    assert any("57600 baud failed its trial" in s for s in said), said
    assert _ram_value(sim_dir, "Po504") == FACTORY
    assert journal.boost_record(d) is None


def test_a_line_lost_while_raised_is_found_and_put_back_by_the_next_command(bus, sim_dir):
    """Every reply lost at the end (a pulled cable): the put-back cannot be proven, the record stays and the
    error says so; the next command (cable back) puts the line back."""
    b = bus(LineFaults())
    [d] = b.drives()
    assert b.sim is not None and b.sim.proxy is not None
    with pytest.raises(boost.LineLeftRaised, match="next command tries both speeds"):
        with boost.line_boost([d], None, sole=True, notice=lambda _l: None) as facts:
            assert facts.raised and facts.baud == 57600
            assert _ram_value(sim_dir, "Po504") == RAISED
            b.sim.proxy.set_faults(LineFaults({"drop": 1.0}))
    assert journal.boost_record(d) is not None
    b.close()
    said: list[str] = []
    res = resolve(ConnectOptions(port="sim", profile="sd25"))
    nxt = Bus(res, notice=said.append)
    try:
        [d2] = nxt.drives()
        assert d2.read_entries([d2.profile.entry("Po504")])[0].raw == FACTORY
    finally:
        nxt.close()
    assert any("ended with the line of unit 1 raised to 57600 baud" in s for s in said), said
    assert _ram_value(sim_dir, "Po504") == FACTORY
    assert journal.boost_record(d2) is None


def test_a_raised_drive_hears_only_its_own_speed(bus, sim_dir):
    """The simulated drive is strict: once Po504 holds 57600 it does not answer at 9600 (it answered the write at
    the old speed)."""
    b = bus()
    [d] = b.drives()
    entry = d.profile.entry("Po504")
    d.write_raw(entry, RAISED)  # answered at 9600
    with pytest.raises(DeviceError, match="no response"):
        d.read_entries([entry])
    b.link.set_line(b.link.line.__class__(57600, "N", 1, 8))
    assert d.read_entries([entry])[0].raw == RAISED
    d.write_raw(entry, FACTORY)
    b.link.set_line(b.link.line.__class__(9600, "N", 1, 8))
    assert d.read_entries([entry])[0].raw == FACTORY


def _sd25_data() -> dict:
    import yaml

    return yaml.safe_load((ROOT / "profiles" / "sd25.yaml").read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"rates": {0: 2400, 5: 57600}}, "no code for the factory line's 9600 baud"),
        ({"to": 115200}, "115200 baud has no code in rates"),
        ({"code": "Po109"}, "Po109 must be a writable entry that takes effect immediately"),
        ({"code": "Po999"}, "names unknown entry 'Po999'"),
        ({"rates": {2: 9600, 9: 57600}}, "a code outside Po504's range 0..5"),
        ({"source": None}, "missing required key 'source'"),
        ({"none": "no faster line"}, "'none' (no boost, and why) goes without code, rates and to"),
    ],
)
def test_the_schema_checks_the_boost_section(change, problem):
    data = _sd25_data()
    data["serial"]["boost"].update(change)
    data["serial"]["boost"] = {k: v for k, v in data["serial"]["boost"].items() if v is not None}
    profile, problems = parse_profile(data, "sd25.yaml")
    assert profile is None and any(problem in p for p in problems), problems


def test_a_drive_that_stores_every_write_cannot_declare_a_boost():
    data = _sd25_data()
    data["persistence"] = {"mode": "immediate"}
    _profile, problems = parse_profile(data, "sd25.yaml")
    assert any("would keep the raised line after a power cycle" in p for p in problems), problems


def test_every_profile_says_whether_and_how_it_raises_its_line():
    for pid in ("sd25", "is620p", "sdc", "dsx7e"):
        b = load_profile(pid).boost
        assert b.available or b.none, pid
        assert b.source, pid
    sd25 = load_profile("sd25").boost
    assert (sd25.code, sd25.to_baud, sd25.unverified != "") == ("Po504", 57600, True)
    assert "PN118" in load_profile("sdc").boost.none


def test_drives_on_a_virtual_link_are_not_raised(sim_dir):
    from servotool.clock import VirtualClock
    from servotool.sim.firmware import build_drive
    from servotool.sim.virtual import VirtualLink

    profile = load_profile("sd25")
    link = VirtualLink([build_drive(profile, 1, persist=False)], VirtualClock())
    with boost.line_boost([Drive(link, profile, 1)], True) as facts:
        assert not facts.raised and facts.baud == 9600


def test_a_plan_with_a_backup_runs_raised_and_one_without_does_not(cli, sim_dir, tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text(f"port: sim\nprofile: sd25\nsteps:\n  - backup: {tmp_path / 'b.yaml'}\n")
    r = cli("run", str(plan), "--yes")
    assert r.code == 0 and "line raised to 57600 baud for the plan" in r.err, r.err
    assert _ram_value(sim_dir, "Po504") == FACTORY
    plan.write_text("port: sim\nprofile: sd25\nsteps:\n  - wait: 0.1\n")
    r = cli("run", str(plan), "--yes")
    assert r.code == 0 and "raised" not in r.err, r.err
