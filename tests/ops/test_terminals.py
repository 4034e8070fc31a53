"""`servotool monitor --io`: every input and output with its level and the function the drive's own parameters
assign it, named as the manual names it (and marked where it does not), live, once and in JSON; the simulated
drives' output monitors follow the functions assigned, as the manuals document them."""

from __future__ import annotations

import pytest

from servotool.drive import Drive
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.loader import load_profile
from servotool.ops.terminals import TerminalReader
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim
from tests.frames import plain_read


def _io(cli, pid: str) -> dict:
    r = cli("--port", "sim", "-P", pid, "monitor", "--io", "--once", "--json")
    assert r.code == 0, r.err
    return r.json()


def _row(data: dict, direction: str, name: str) -> dict:
    return next(t for t in data[direction] if t["terminal"] == name)


def test_each_profile_shows_its_terminals_with_the_functions_its_parameters_assign(cli):
    is620p = _io(cli, "is620p")
    assert [t["terminal"] for t in is620p["inputs"]] == [f"DI{n}" for n in range(1, 10)]
    di1 = _row(is620p, "inputs", "DI1")
    assert di1["function_number"] == 14 and di1["function"].startswith("14 P-OT")  # H03-02 factory 14
    assert di1["set_by"] == "H03-02" and di1["logic"] == "H03-03 = 0"
    assert "general IS620P manual" in di1["unverified"]  # this volume prints no DI table
    assert _row(is620p, "inputs", "DI6")["unverified"] is None  # FunIN.12 (zero clamp) is in this volume (L2589)
    assert is620p["inputs_monitor"] == "H0B-03" and is620p["outputs_monitor"] == "H0B-05"

    sd25 = _io(cli, "sd25")
    assert _row(sd25, "inputs", "DI7")["function"] == "34 Touchprobe-1, touch probe 1 (edge)"  # Po413 d 1 34
    unnamed = _row(sd25, "inputs", "DI1")  # Po407.X = 0: reserved in the manual's table
    assert unnamed["named_by_manual"] is False and "reserved" in unnamed["why_not_named"]
    assert _row(sd25, "outputs", "ALM")["set_by"] == "Po425.X"

    sdc = _io(cli, "sdc")
    assert _row(sdc, "inputs", "IN1")["function"] == "probe 2 / negative limit"
    assert _row(sdc, "outputs", "OUT2")["set_by"] == "fixed"

    dsx7e = _io(cli, "dsx7e")
    assert _row(dsx7e, "inputs", "DI1")["function"] == "1, not named"  # the manual prints no DI function table
    assert _row(dsx7e, "outputs", "DO2")["function"] == "6 BK, holding brake (unverified)"


def test_the_simulated_outputs_follow_the_functions_assigned(cli, sim_dir):
    data = _io(cli, "is620p")  # factory: DO1 S-RDY, DO2 COIN, DO3 ZERO, DO4 ALM, DO5 HomeAttain
    assert [t["level"] for t in data["outputs"]] == [1, 0, 1, 0, 0]  # ready, standing still, no alarm
    assert cli("--port", "sim", "-P", "is620p", "param", "set", "H04-00=11").code == 0  # DO1 := ALM
    sim_drive = build_drive(load_profile("is620p"), 1)
    with sim_drive.session():
        sim_drive.firmware.trip("overload")
        sim_drive.bank.save()
    data = _io(cli, "is620p")
    assert _row(data, "outputs", "DO1")["function"].startswith("11 ALM") and _row(data, "outputs", "DO1")["level"] == 1
    assert _row(data, "outputs", "DO4")["level"] == 1
    sdc = _io(cli, "sdc")
    assert [t["level"] for t in sdc["outputs"]] == [0, 0]  # brake held (servo off), no alarm


def test_the_levels_are_the_monitors_bits_as_an_independent_reader_sees_them(sim_dir):
    profile = load_profile("dsx7e")
    sim_drive = build_drive(profile, 1)
    sim_drive.bank.set_live("Un032", 0b1000_0101)  # DI1, DI3 and DI8 closed (what wiring would do)
    sim = EmbeddedSim([sim_drive])
    link = RtuMaster(LinkSettings(port=sim.port, timeout=0.5, retries=0))
    try:
        reader = TerminalReader(Drive(link, profile, 1))
        reader.read_assignments()
        levels = reader.read_levels()
        assert plain_read(sim.port, profile.entry("Un032").address, 1) == [0b1000_0101]
    finally:
        link.close()
        sim.close()
    assert [name for name, on in levels.inputs.items() if on] == ["DI1", "DI3", "DI8"]
    assert reader.assignments["inputs"][2].set_by == "Pn402"


def test_monitor_io_once_is_a_table_per_group_with_the_manuals_gaps_said_below(cli):
    r = cli("--port", "sim", "-P", "is620p", "monitor", "--io", "--once", env={"COLUMNS": "80"})
    assert r.code == 0, r.err
    assert "inputs (H0B-03)" in r.out and "outputs (H0B-05)" in r.out
    di1 = r.out[r.out.index("│ DI1") : r.out.index("│ DI2")]
    assert "14 P-OT, forward" in di1 and "(unverified)" in di1, r.out
    assert "inputs function 0: not named in this volume" in r.out
    assert all(len(line) <= 80 for line in r.out.splitlines()), r.out


def test_monitor_io_piped_prints_a_line_when_the_levels_change_then_the_table(cli):
    r = cli("--port", "sim", "-P", "is620p", "monitor", "--io", "--duration", "0.3", "--rate", "20")
    assert r.code == 0, r.err
    first = r.out.splitlines()[0]
    assert first.endswith("on: DO1 DO3"), r.out  # S-RDY and ZERO: one line, the levels never change
    assert sum(line.endswith("on: DO1 DO3") for line in r.out.splitlines()) == 1
    assert "outputs (H0B-05)" in r.out and "samples in" in r.err


@pytest.mark.parametrize(
    ("args", "words"),
    [(("Un000",), "give no codes"), (("--csv", "x.csv"), "--csv or --plot"), (("--plot",), "--csv or --plot")],
)
def test_monitor_io_refuses_what_it_cannot_show(cli, args, words):
    r = cli("--port", "sim", "monitor", "--io", *args)
    assert r.code == 2 and words in r.err and len(r.err.strip().splitlines()) <= 2, r.err
