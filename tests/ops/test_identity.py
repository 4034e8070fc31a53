"""Identity before any write: each shipped profile's checks against simulated drives of every profile."""

from __future__ import annotations

import pytest
import yaml

from servotool.connection import ConnectOptions, resolve
from servotool.errors import IdentityMismatch
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.loader import builtin_dir, builtin_ids, load_profile
from servotool.model.schema import parse_profile
from servotool.ops.identity import MATCH, MISMATCH, identify
from servotool.session import open_drives
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim

IDS = builtin_ids()


@pytest.fixture(scope="module")
def bus():
    """One simulated drive of every shipped profile on one line, unit n+1 for the n-th profile."""
    sim = EmbeddedSim([build_drive(load_profile(pid), i + 1, persist=False) for i, pid in enumerate(IDS)])
    link = RtuMaster(LinkSettings(port=sim.port, timeout=0.3, retries=0))
    yield sim, link
    link.close()
    sim.close()


@pytest.mark.parametrize("pid", IDS)
def test_each_profile_matches_its_own_drive_and_no_other(bus, pid):
    _sim, link = bus
    profiles = [load_profile(p) for p in IDS]
    for unit, actual in enumerate(IDS, start=1):
        verdicts = {v.profile.id: v.outcome for v in identify(link, unit, profiles)}
        assert verdicts[pid] == (MATCH if pid == actual else MISMATCH), (pid, actual, verdicts)


def test_simulated_drive_answers_the_manuals_identity_values(bus):
    _sim, link = bus
    sd25 = identify(link, IDS.index("sd25") + 1, [load_profile("sd25")])[0]
    dsx7e = identify(link, IDS.index("dsx7e") + 1, [load_profile("dsx7e")])[0]
    sdc = identify(link, IDS.index("sdc") + 1, [load_profile("sdc")])[0]
    assert sd25.firmware == 100  # So-00: "100 = V1.00"
    assert dsx7e.model == 0x31 and sdc.firmware == 4007


@pytest.mark.parametrize(
    ("actual", "claimed", "code"), [("sd25", "sdc", "PN17"), ("dsx7e", "is620p", "H02-00"), ("is620p", "sd25", "Po017")]
)
def test_mismatch_is_refused_before_anything_is_written(sim_dir, actual, claimed, code):
    drive = build_drive(load_profile(actual), 1, persist=False)
    before = (dict(drive.bank.ram), drive.bank.eeprom_writes)
    sim = EmbeddedSim([drive])
    try:
        writes = []
        with (
            pytest.raises(IdentityMismatch) as err,
            open_drives(resolve(ConnectOptions(port=sim.port, profile=claimed))) as (d,),
        ):
            writes.append(d.write_raw(d.profile.entry(code), 1))
    finally:
        sim.close()
    assert not writes and (dict(drive.bank.ram), drive.bank.eeprom_writes) == before
    assert err.value.better == (actual, load_profile(actual).model) and err.value.exit_code == 2
    assert f"profile {claimed}" in str(err.value) and f"--profile {actual}" in str(err.value)


def test_no_identity_check_goes_on(sim_dir):
    drive = build_drive(load_profile("sd25"), 1, persist=False)
    sim = EmbeddedSim([drive])
    try:
        opts = ConnectOptions(port=sim.port, profile="sdc", no_identity_check=True)
        with open_drives(resolve(opts)) as (d,):
            assert d.read_one("PN17").raw == drive.bank.value("Po017")
    finally:
        sim.close()


def test_inconclusive_check_warns_once_for_all_units(sim_dir, tmp_path):
    data = yaml.safe_load((builtin_dir() / "sd25.yaml").read_text(encoding="utf-8"))
    del data["identity"]
    data["id"] = "mysd25"
    path = tmp_path / "mysd25.yaml"
    path.write_text(yaml.safe_dump(data, allow_unicode=True), encoding="utf-8")
    sim = EmbeddedSim([build_drive(load_profile("sd25"), u, persist=False) for u in (1, 2)])
    notes: list[str] = []
    try:
        with open_drives(
            resolve(ConnectOptions(port=sim.port, profile=str(path))), [1, 2], notice=notes.append
        ) as drives:
            assert len(drives) == 2
    finally:
        sim.close()
    assert len(notes) == 1 and "warning: cannot confirm" in notes[0]
    assert "unit 1" in notes[0] and "unit 2" in notes[0]


@pytest.fixture(scope="module")
def sd25_data():
    return yaml.safe_load((builtin_dir() / "sd25.yaml").read_text(encoding="utf-8"))


@pytest.mark.parametrize(
    ("change", "problem"),
    [
        ({"checks": [{"code": "So-00", "range": [100, 9999], "sim": 5, "source": "x"}]}, "outside the check's range"),
        ({"checks": [{"address": 800, "absent": True, "source": "x"}]}, "belongs to an entry"),
        ({"firmware": "So-60", "checks": [{"code": "So-00", "source": "x"}]}, "must also be one of the checks"),
        ({"checks": [{"code": c, "source": "x"} for c in ("So-00", "So-46", "So-60")]}, "more than 2 read requests"),
    ],
)
def test_schema_refuses_a_broken_identity_section(sd25_data, change, problem):
    profile, problems = parse_profile({**sd25_data, "identity": change}, "sd25.yaml")
    assert profile is None and len(problems) == 1 and problem in problems[0] and "identity" in problems[0]


class _Refusing:
    """A link whose drive answers every read with one Modbus exception."""

    def __init__(self, code: int) -> None:
        self.code = code

    def read(self, unit, address, count, *, spare=(0, 0)):
        from servotool.errors import ModbusException

        raise ModbusException(self.code, f"unit {unit}")


def test_an_exception_other_than_02_tells_nothing():
    from servotool.ops.identity import INCONCLUSIVE, probe, warning_text

    verdict = probe(_Refusing(4), 1, load_profile("sd25"))
    assert verdict.outcome == INCONCLUSIVE
    assert "So-00 (address 800): exception 04" in warning_text([verdict])
    assert probe(_Refusing(2), 1, load_profile("sd25")).outcome == MISMATCH


def test_answers_for_one_profile_rule_out_maps_that_cannot_give_them(bus):
    from servotool.ops.identity import consistent, probe

    _sim, link = bus
    answers = probe(link, IDS.index("sd25") + 1, load_profile("sdc")).answers  # PN1/PN2 read from an SD25
    assert consistent(load_profile("sd25"), answers)
    assert not consistent(load_profile("is620p"), answers) and not consistent(load_profile("dsx7e"), answers)
