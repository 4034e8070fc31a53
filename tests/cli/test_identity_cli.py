"""`-P sdc` against a simulated SD25: refused before the write, one line, exit 2; --no-identity-check goes on."""

from __future__ import annotations

import pytest

from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


@pytest.fixture
def sd25():
    drive = build_drive(load_profile("sd25"), 1, persist=False)
    sim = EmbeddedSim([drive])
    yield drive, sim.port
    sim.close()


def test_wrong_profile_is_refused_and_nothing_is_written(cli, sd25):
    drive, port = sd25
    before = dict(drive.bank.ram)
    r = cli("--port", port, "-P", "sdc", "param", "set", "PN17=300")
    assert r.code == 2 and r.out == ""
    assert len(r.err.strip().splitlines()) == 1, r.err
    assert "profile sdc" in r.err and "--profile sd25" in r.err and "nothing was written" in r.err
    assert dict(drive.bank.ram) == before and drive.bank.value("Po017") != 300


@pytest.mark.parametrize("how", ["flag", "env"])
def test_no_identity_check_overrides(cli, sd25, how):
    drive, port = sd25
    args, env = (["--no-identity-check"], None) if how == "flag" else ([], {"SERVOTOOL_NO_IDENTITY_CHECK": "1"})
    r = cli("--port", port, "-P", "sdc", *args, "param", "set", "PN17=300", env=env)
    assert r.code == 0, r.err
    assert drive.bank.value("Po017") == 300  # what the override is for: the user takes the risk
