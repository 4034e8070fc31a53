"""tune inertia through the CLI on the simulated drive, the drive-side method, and its refusals."""

from __future__ import annotations

import pytest

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.profile import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim
from servotool.transport import LinkSettings, ModbusLink
from servotool.tuning import wizard


@pytest.mark.parametrize("ratio", [0.0, 6.0, 30.0])
def test_tune_identifies_the_configured_load_and_writes_it(cli, ratio):
    assert cli("sim", "config", "--load-ratio", str(ratio), "--friction", "0.03", "--load-torque", "0.05").code == 0
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--json", "--no-gains")
    assert r.code == 0, r.err
    res = r.json()
    assert res["ratio"] == pytest.approx(ratio, abs=0.05 * max(ratio, 1.0))
    assert res["written"] is True and res["travel_rev"] <= 2.0
    assert res["load_torque_nm"] == pytest.approx(0.05 * 1.27, abs=0.01)
    value = cli("--port", "sim", "param", "get", "Pn004", "--json").json()[0]["value"]
    assert value == pytest.approx(res["parameter_value"])
    assert value == pytest.approx((ratio + 1) * 100, abs=0.05 * (ratio + 1) * 100)


def test_tune_sets_gains_for_a_rigidity_and_saves_the_trace(cli, tmp_path):
    cli("sim", "config", "--load-ratio", "4")
    trace = tmp_path / "trace.csv"
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--json", "--rigidity", "14", "--save-trace", str(trace))
    assert r.code == 0, r.err
    gains = {g["role"]: g for g in r.json()["gains"]}
    assert set(gains) == {"speed_loop_gain", "speed_loop_integral", "position_loop_gain", "torque_filter"}
    now = cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"]
    assert now == pytest.approx(gains["speed_loop_gain"]["new"])
    lines = trace.read_text().splitlines()
    assert lines[0] == "t_s,speed_rpm,torque_pct,position_rev" and len(lines) > 100


def test_dry_run_writes_nothing(cli):
    cli("sim", "config", "--load-ratio", "3")
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--dry-run", "--json")
    assert r.code == 0 and r.json()["written"] is False
    assert cli("--port", "sim", "param", "get", "Pn004", "--json").json()[0]["value"] == 250


def test_drive_method_uses_the_drive_identification(cli):
    cli("sim", "config", "--load-ratio", "5")
    r = cli("--port", "sim", "tune", "inertia", "--method", "drive", "--yes", "--json", "--no-gains")
    assert r.code == 0, r.err
    assert r.json()["ratio"] == pytest.approx(5.0, rel=0.08)


def test_refusals(cli):
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--travel", "0.05")
    assert r.code == 2 and "too small" in r.err
    r = cli("--port", "sim", "tune", "inertia", "--json")
    assert r.code == 2 and "--yes" in r.err                    # no TTY, no --yes: nothing moves
    r = cli("--port", "tcp://127.0.0.1:9", "--profile", "dsx7e", "tune", "inertia", "--yes")
    assert r.code == 1 and "cannot open port" in r.err
    r = cli("--port", "sim", "--profile", "sdc", "tune", "inertia", "--yes")    # PN60 semantics unknown
    assert r.code == 2 and "needs role 'inertia_ratio'" in r.err


def test_active_alarm_refuses_before_any_motion(sim_dir):
    profile = load_profile("dsx7e")
    sim_drive = build_drive(profile, 1)
    sim = EmbeddedSim([sim_drive])
    try:
        sim_drive.firmware._trip("overload")
        link = ModbusLink(LinkSettings(port=sim.port, timeout=0.5, retries=0))
        with pytest.raises(UsageError, match="alarm E09"):
            wizard.preflight(Drive(link, profile, 1), "host")
        link.close()
    finally:
        sim.close()


def test_step_check_shows_the_better_response_after_tuning(cli):
    cli("sim", "config", "--load-ratio", "10")
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--json", "--step-check", "--rigidity", "15")
    assert r.code == 0, r.err
    before, after = r.json()["step_before"], r.json()["step_after"]
    assert before["samples"] > 20 and after["samples"] > 20
    assert after["overshoot_pct"] < before["overshoot_pct"]       # default ratio 1.5 vs true 10: under-damped
