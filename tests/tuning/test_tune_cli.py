"""tune inertia through the CLI on the simulated drive, the drive-side method, and its refusals."""

from __future__ import annotations

import socket
import time

import pytest

from tests.tuning.realtime_cli import (
    LOADED_J_SHARE,
    STALL_WORDS,
    assert_said,
    cli_ok,
    near,
    tune_json,
    tune_ok,
)


@pytest.mark.parametrize("ratio", [0.0, 6.0, 30.0])
def test_tune_identifies_the_configured_load_and_writes_it(cli, ratio):
    # friction above the load torque: the axis stays put with the servo off (no brake in this machine)
    assert cli("sim", "config", "--load-ratio", str(ratio), "--friction", "0.06", "--load-torque", "0.05").code == 0
    _r, res = tune_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--no-gains", "--travel", "12")
    assert near(res, ratio), res
    assert res["written"] is True and res["travel"]["value"] <= 12.0
    # 1.2 % of rated torque: a run in CI on two busy cores read 0.053 (the in-process simulated drive stalls too)
    assert res["load_torque"]["value"] == pytest.approx(0.05 * 1.27, abs=0.015)
    assert res["load_torque"]["std"] > 0 and res["coulomb"]["std"] > 0
    value = cli("--port", "sim", "param", "get", "Pn004", "--json").json()[0]["value"]
    assert value == pytest.approx(res["parameter_value"]["value"]) and res["parameter_value"]["unit"] == "%"
    assert value == pytest.approx((ratio + 1) * 100, abs=LOADED_J_SHARE * (ratio + 1) * 100)


# The IS620P segment route's setup (profiles/is620p.yaml motion_setup), as a user types it.
IS620P_SETUP = ("H02-00=1", "H05-00=2", "H05-02=10000", "H11-00=0", "H0C-09=1", "H17-00=1", "H17-02=28")


def test_tune_sets_gains_for_a_rigidity_and_saves_the_trace(cli, tmp_path):
    cli("sim", "config", "--load-ratio", "4")
    trace = tmp_path / "trace.csv"
    tune = ("--port", "sim", "tune", "inertia", "--yes", "--rigidity", "14", "--save-trace", str(trace), "--travel")
    r, _res = tune_ok(cli, *tune, "12")
    gains = {g["role"]: g for g in r.json()["gains"]}
    assert set(gains) == {"speed_loop_gain", "speed_loop_integral", "position_loop_gain", "torque_filter", "rigidity"}
    assert gains["rigidity"]["code"] == "Pn003" and gains["rigidity"]["new"] == 14  # DSX7E's own level, written
    assert r.json()["phase_margin"]["value"] >= 45 and r.json()["gain_margin"]["value"] >= 6
    now = cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"]
    assert now == pytest.approx(gains["speed_loop_gain"]["new"])
    lines = trace.read_text().splitlines()
    assert lines[0] == "t_s,speed_rpm,torque_pct,position_rev" and len(lines) > 100


def _params(cli, *codes):
    return {p["code"]: p["value"] for p in cli("--port", "sim", "param", "get", *codes, "--json").json()}


def test_dry_run_writes_nothing(cli):
    cli("sim", "config", "--load-ratio", "3")
    before = _params(cli, "Pn004", "Pn100", "Pn101", "Pn102", "Pn128")
    # A log that is refused still writes nothing; --repeats 2 and ramps of 100 ms keep the run short and its
    # outcome (identified or refused) is not what this test is about.
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--dry-run", "--json", "--rigidity", "12", "--travel", "12")
    data = r.json()
    assert data["written"] is False and data.get("gains_written", False) is False
    assert _params(cli, "Pn004", "Pn100", "Pn101", "Pn102", "Pn128") == before


def test_gains_are_left_alone_unless_asked_for(cli):
    cli("sim", "config", "--load-ratio", "4")
    before = _params(cli, "Pn100", "Pn101", "Pn102", "Pn128")
    r, _res = tune_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--travel", "12")
    assert r.json()["gains"] == [] and r.json()["written"] is True
    assert _params(cli, "Pn100", "Pn101", "Pn102", "Pn128") == before


def test_result_is_shown_before_the_write_is_confirmed(cli):
    cli("sim", "config", "--load-ratio", "4")
    r = cli_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--rigidity", "14", "--travel", "12")
    assert r.out.index("1.50 ->") < r.out.index("Suggested") < r.out.index("Pn004 written")


def test_drive_method_dry_run_puts_the_old_ratio_back(cli):
    cli("sim", "config", "--load-ratio", "5")
    r = cli("--port", "sim", "tune", "inertia", "--method", "drive", "--yes", "--json", "--dry-run", "--travel", "12")
    assert r.code == 0, r.err
    data = r.json()
    assert data["written"] is False and data["ratio"] == pytest.approx(5.0, rel=0.08)
    assert data["travel"] is None  # JSON null, not NaN
    assert _params(cli, "Pn004")["Pn004"] == 250


@pytest.mark.parametrize(
    "args, message",
    [
        (("--travel", "nan"), "--travel must be a number"),
        (("--rigidity", "40"), "rigidity must be 0..31 (this drive's own levels, factory 13)"),
        (("--bandwidth", "5000"), "bandwidth must be"),
        (("--save-trace", "/nonexistent-dir/t.csv"), "cannot write the trace"),
        (("--step-check", "--travel", "0.5"), "--step-check needs"),
        (("--direction", "sideways"), "--direction must be"),
        (("--accel-time", "nan"), "--accel-time must be"),
    ],
)
def test_bad_options_are_refused_before_anything_moves(cli, args, message):
    cli("sim", "config", "--load-ratio", "3")
    r = cli("--port", "sim", "tune", "inertia", "--yes", *args)
    assert r.code == 2 and message in r.err and "Traceback" not in r.err
    assert len(r.err.strip().splitlines()) <= 2  # the sim banner and one error line
    assert "pilot" not in r.err


def test_one_direction_identifies_with_friction_and_load_torque_combined(cli):
    cli("sim", "config", "--load-ratio", "6", "--friction", "0.03")
    # 16 rev: six moves one way with room to accelerate, and a dead host's run-on inside the travel (at 8 rev the
    # moves were held to 407 rpm and a busy host left them 3.4 % uncertain: refused 1 in 2 with two CPU burners)
    r, res = tune_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--direction", "forward", "--travel", "16")
    assert near(res, 6.0) and res["travel"]["value"] <= 16.0
    assert any("one direction" in n for n in r.json()["notes"])


def test_falling_axis_is_refused_before_any_motion_and_identified_once_a_brake_holds_it(cli):
    cli("sim", "config", "--load-ratio", "3", "--friction", "0.01", "--load-torque", "0.1", "--brake", "off")
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--travel", "12")
    assert r.code == 2 and "moving with the servo off" in r.err and "pilot" not in r.err
    cli("sim", "reset", "--power-cycle")  # the fallen axis at rest again
    cli("sim", "config", "--brake", "on")
    _r, res = tune_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--travel", "12")
    assert near(res, 3.0), res


def test_refusal_writes_the_trace_and_a_json_reason(cli, tmp_path):
    """Too noisy for 2 % within one cycle over 1 rev, refused however loaded the host (a stall only makes it worse):
    the trace is saved, the reason goes to JSON, nothing is written. The travel the refusal names, where it names one,
    is in its words for a script too (whether it helps: test_remedy.py on virtual time, SD25 at 9600)."""
    cli("sim", "config", "--load-ratio", "3", "--noise", "0.03")
    trace = tmp_path / "t.csv"
    r = cli(
        "--port",
        "sim",
        "tune",
        "inertia",
        "--yes",
        "--json",
        "--repeats",
        "1",
        "--travel",
        "3",  # with DSX7E's 500 ms watchdog's run-on inside it: 200 rpm
        "--save-trace",
        str(trace),
    )
    assert r.code == 1
    data = assert_said(r)
    assert data["ok"] is False and data["written"] is False
    suggested = (data["suggested_travel"] or {}).get("value")
    if "refused" in data["reason"] and suggested is not None:
        assert data["suggested_travel"]["unit"] == "rev" and f"--travel {suggested:g} " in data["reason"]
    assert "NaN" not in r.out
    assert len(trace.read_text().splitlines()) > 20
    assert _params(cli, "Pn004")["Pn004"] == 250


def test_drive_method_uses_the_drive_identification(cli):
    cli("sim", "config", "--load-ratio", "5")
    # The host identification that checks the drive's result needs room for DSX7E's watchdog run-on at speed.
    _r, res = tune_ok(
        cli, "--port", "sim", "tune", "inertia", "--method", "drive", "--yes", "--no-gains", "--travel", "12"
    )
    assert res["ratio"] == pytest.approx(5.0, rel=0.08)


def test_refusals(cli):
    r = cli("--port", "sim", "tune", "inertia", "--yes", "--travel", "0.05")
    assert r.code == 2 and "too small" in r.err
    r = cli("--port", "sim", "tune", "inertia", "--json")
    assert r.code == 2 and "--yes" in r.err  # no TTY, no --yes: nothing moves
    r = cli("--port", "tcp://127.0.0.1:9", "--profile", "dsx7e", "tune", "inertia", "--yes")
    assert r.code == 1 and "cannot open port" in r.err
    with socket.socket() as silent:  # a gateway that accepts but never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        port = f"tcp://127.0.0.1:{silent.getsockname()[1]}"
        start = time.monotonic()
        r = cli("--port", port, "--profile", "dsx7e", "--timeout", "0.3", "tune", "inertia", "--yes")
        assert r.code == 1 and "no response" in r.err and len(r.err.strip().splitlines()) == 1, r.err
        assert time.monotonic() - start < 15
    r = cli("--port", "sim", "--profile", "sdc", "tune", "inertia", "--yes", "--method", "drive")
    assert r.code == 2 and "no way to reach the inertia ratio of this drive" in r.err


def test_a_drive_without_an_inertia_ratio_parameter_is_identified_and_nothing_is_written(cli):
    """SDC maps no inertia-ratio parameter (PN60's meaning is unknown) and no usable position feedback: the host
    method still measures the load, tracking travel from the speed, and reports it without writing."""
    cli("sim", "config", "--profile", "sdc", "--load-ratio", "5")
    assert cli("--port", "sim", "--profile", "sdc", "param", "set", "PN4=3").code == 0  # the JOG route's setup
    # A moderate speed: at the automatic speed a move covers 1.8 of the 2 rev, and a stall of this process on a busy
    # machine (60-200 ms measured) lets the real-time simulated motor run past the travel guard (or, without
    # position feedback, makes the travel integrated from the speed overshoot it). Not issue 16's growing hold
    # oscillation, which is gone (bench/hold_stability.py). This test is about a drive without a ratio parameter,
    # so its travel limit leaves room for a 200 ms stall at full speed (2 rev at 600 rpm; CI failed once with 2).
    sdc = ("--port", "sim", "--profile", "sdc", "tune", "inertia", "--yes", "--max-speed", "600", "--travel", "4")
    _r, res = tune_ok(cli, *sdc, "--no-dead-man")
    assert near(res, 5.0) and res["travel"]["value"] <= 4.0
    assert res["old_ratio"] is None and res["parameter"] is None and res["written"] is False
    r = cli_ok(cli, *sdc, "--no-dead-man")
    assert "not a drive parameter" in r.out and "nothing to write" in r.out


def test_step_check_shows_the_better_response_after_tuning(cli):
    cli("sim", "config", "--load-ratio", "10")
    r, _res = tune_ok(
        cli, "--port", "sim", "tune", "inertia", "--yes", "--step-check", "--rigidity", "15", "--travel", "12"
    )
    before, after = r.json()["step_before"], r.json()["step_after"]
    assert before["samples"] > 20 and after["samples"] > 20
    assert after["overshoot"]["value"] < before["overshoot"]["value"]  # default ratio 1.5 vs true 10: under-damped


def test_motion_stays_inside_a_small_travel_limit(cli):
    cli("sim", "config", "--load-ratio", "30")  # far from the configured 1.5: the loop overshoots
    r, res = tune_json(cli, "--port", "sim", "tune", "inertia", "--yes", "--travel", "1", "--no-gains")
    if "travel" in res:  # whatever the outcome, the axis moved inside the limit
        assert res["travel"]["value"] <= 1.0, res
    else:  # stopped before a travel was measured (a busy host's stall tripped the drive's watchdog): said, stopped
        assert r.code == 1 and r.err.splitlines()[-1].startswith("servotool: stopped"), r.err
    if r.code == 1:  # refused for the short travel (naming one), or stopped by a stall the words name as such
        assert "travel" in res["reason"] or any(w in res["reason"] for w in STALL_WORDS), res["reason"]


def test_identification_works_wherever_the_axis_stands(cli):
    """The travel band is set around the axis's real position, not around position 0."""
    cli("sim", "config", "--load-ratio", "5")
    assert cli("--port", "sim", "jog", "--speed", "-300", "--time", "1").code == 0  # 5 rev below zero
    _r, res = tune_ok(cli, "--port", "sim", "tune", "inertia", "--yes", "--travel", "12")
    assert near(res, 5.0) and res["travel"]["value"] <= 12.0


def test_drive_method_is_refused_up_front_where_its_end_cannot_be_seen(cli):
    """SD25 starts its own identification with Po008 but shows no 'identifying' status: no 30 s blind wait."""
    start = time.monotonic()
    r = cli("--port", "sim", "--profile", "sd25", "tune", "inertia", "--yes", "--method", "drive")
    assert r.code == 2 and "--method host" in r.err and len(r.err.strip().splitlines()) <= 2
    assert time.monotonic() - start < 10


def test_an_axis_switched_on_from_elsewhere_is_not_moved_nor_switched_off(cli):
    """IS620P's servo-on is a parameter (VDI H31-00): set by someone else, tune must refuse and leave it on."""
    assert cli("--port", "sim", "--profile", "is620p", "param", "set", *IS620P_SETUP, "H31-00=1").code == 0
    r = cli("--port", "sim", "--profile", "is620p", "tune", "inertia", "--yes")
    assert r.code == 2 and "servo is on" in r.err
    r = cli("--port", "sim", "--profile", "is620p", "param", "get", "H31-00", "H08-15", "--json")
    assert [row["changed"] for row in r.json()] == [True, False]  # still on, ratio untouched


def test_tune_gains_prints_the_levels_tried_and_keeps_one(cli):
    cli("sim", "config", "--load-ratio", "3")
    assert cli("--port", "sim", "param", "set", "Pn004=400").code == 0  # as tune inertia would write it
    r = cli_ok(cli, "--port", "sim", "tune", "gains", "--yes", "--json", "--from", "16", "--to", "18")
    res = r.json()
    levels = [row["level"] for row in res["levels"]]
    assert levels[0] == 16 and levels == list(range(16, 16 + len(levels))) and res["chosen"] in levels
    assert all(row["phase_margin"]["value"] >= 45 for row in res["levels"])
    # Idle, every level passes its step check and 18 is kept; a loaded host's step check may see a stall's
    # overshoot (named in the level's failure) and back off to the last level that passed.
    kept = [row for row in res["levels"] if row["level"] <= res["chosen"]]
    assert all(row["failure"] is None for row in kept)
    assert res["chosen"] == 18 or res["levels"][-1]["failure"], res
    assert _params(cli, "Pn003")["Pn003"] == res["chosen"]
