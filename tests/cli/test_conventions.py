"""Conventions of the ecosystem: options anywhere, help once, JSON errors, Ctrl-C 130, line-buffered pipes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import typer

from servotool.cli.argv import hoist_globals
from servotool.cli.main import app

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def root():
    return typer.main.get_command(app)


@pytest.mark.parametrize(
    ("given", "hoisted"),
    [
        (["param", "get", "Pn101", "--port", "sim"], ["--port", "sim", "param", "get", "Pn101"]),
        (
            ["param", "set", "Pn101=2", "-P", "is620p", "--save", "-vv"],
            ["-P", "is620p", "-vv", "param", "set", "Pn101=2", "--save"],
        ),
        (
            ["--port", "sim", "jog", "--speed", "-5", "--time", "1", "-q"],
            ["-q", "--port", "sim", "jog", "--speed", "-5", "--time", "1"],
        ),
        (
            ["sim", "serve", "--port", "tcp://127.0.0.1:0", "--unit", "3"],
            ["sim", "serve", "--port", "tcp://127.0.0.1:0", "--unit", "3"],
        ),  # serve's own options
        (["alarm", "--json", "show", "--port", "sim"], ["--port", "sim", "alarm", "show", "--json"]),
        (["param", "get", "--", "--port"], ["param", "get", "--", "--port"]),
        (["--json", "--port", "sim", "param", "get", "Pn004"], ["--port", "sim", "param", "get", "--json", "Pn004"]),
        (["-q", "--json", "alarm", "show"], ["-q", "alarm", "show", "--json"]),
    ],
)
def test_global_options_after_the_sub_command_are_moved_before_it(root, given, hoisted):
    assert hoist_globals(root, given) == hoisted


def test_options_after_the_sub_command_work_end_to_end(cli):
    r = cli("param", "get", "Pn004", "--port", "sim", "--json")
    assert r.code == 0 and r.json()[0]["value"] == 250
    r = cli("alarm", "--json", "show", "--port", "sim")
    assert r.code == 0 and r.json()["active"] is False


@pytest.mark.parametrize("args", [(), ("param",), ("sim",), ("tune",)])
def test_help_is_printed_once(cli, args):
    r = cli(*args)
    assert (r.out + r.err).count("Usage:") == 1


def test_a_mistyped_command_gets_the_close_ones(cli):
    r = cli("parm", "get", "Pn004")
    assert r.code == 2 and "No such command 'parm'. Did you mean 'param'" in r.err
    r = cli("param", "gt", "Pn004")
    assert r.code == 2 and "Did you mean 'get'?" in r.err


def test_completion_options_belong_to_the_root_help_only(cli):
    assert "--install-completion" in cli("--help").out
    for command in ("scan", "jog", "monitor"):
        r = cli(command, "--help")
        assert r.code == 0 and "Usage:" in r.out and "--install-completion" not in r.out


def test_the_cli_module_runs_as_a_script_too(cli):
    r = subprocess.run(
        [sys.executable, "-m", "servotool.cli.main", "--version"], capture_output=True, text=True, cwd=ROOT, timeout=60
    )
    assert r.returncode == 0 and r.stdout.startswith("servotool ")


def test_with_json_an_error_is_a_json_object_too(cli):
    r = cli("--port", "sim", "param", "get", "Pn999", "--json")
    assert r.code == 2
    error = r.json()["error"]
    assert error["code"] == "unknown_name" and "Pn999" in error["message"] and error["exit_status"] == 2
    assert "servotool: error: unknown code 'Pn999'" in r.err
    r = cli("--port", "sim", "param", "get", "Pn004", "--json", "--bogus")
    assert r.code == 2 and r.json()["error"]["code"] == "usage" and "--bogus" in r.err


def test_a_timeout_is_one_line_and_leaves_no_asyncio_noise(cli_process):
    r = cli_process(  # a process: asyncio's noise is printed at the interpreter's exit
        "--port", "sim", "--timeout", "0.001", "--retries", "0", "param", "list"
    )
    assert r.code == 1 and "no response" in r.err
    assert "Task was destroyed" not in r.err and "Traceback" not in r.err


def test_piped_monitor_streams_lines_and_ctrl_c_exits_130(sim_dir):
    env = {**os.environ, "COLUMNS": "100"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "--port", "sim", "monitor", "--json", "Un000"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
    )
    try:
        first = proc.stdout.readline()  # arrives while the command still runs: line-buffered
        assert '"Un000"' in first and '"unit": "rpm"' in first
        proc.send_signal(signal.SIGINT)
        rest, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "servotool: interrupted" in err
    lines = [json.loads(line) for line in (first + rest).splitlines()]  # still JSON lines, the error too
    assert lines[-1]["error"]["exit_status"] == 130


def test_sim_serve_at_ctrl_c_stops_and_exits_130(sim_dir):
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "sim", "serve", "--port", "tcp://127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert "serving on" in proc.stderr.readline()
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "simulator stopped" in err


def test_plain_monitor_at_ctrl_c_prints_what_it_has_and_exits_130(sim_dir):
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "--port", "sim", "monitor", "Un000"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={**os.environ, "COLUMNS": "100"},
    )
    try:
        assert "SIMULATED" in proc.stderr.readline()
        first = proc.stdout.readline()  # each sample a line as it comes, through the pipe
        assert " s  Un000 " in first and first.strip().endswith("rpm"), first
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "│ Un000 │ Motor speed" in out and "servotool: interrupted" in err


def test_an_option_value_that_looks_like_an_option_is_refused_before_anything_runs(cli):
    """`monitor --csv --json` would write a file named '--json': the value was left out."""
    r = cli("--port", "sim", "monitor", "--once", "--csv", "--json")
    assert r.code == 2 and "'--json' looks like an option" in r.err and "Traceback" not in r.err
    assert not (Path(__file__).resolve().parents[2] / "--json").exists()  # the tests run in the repository


def test_quiet_keeps_results_and_errors(cli, tmp_path):
    r = cli("-q", "--port", "sim", "jog", "--speed", "100", "--time", "0.2")
    assert r.code == 0 and "JOG done: peak" in r.err and "SIMULATED" not in r.err  # the banner goes
    assert "JOG forward at" not in r.err  # progress words go
    assert "if this program stops, the motor stops within" in r.err  # the safety line stays (issue 29)
    assert r.err.strip().splitlines()[-1].startswith("servotool: stopped, servo off")  # so does the stop's proof
    plan = tmp_path / "plan.yaml"
    plan.write_text("port: sim\nprofile: dsx7e\nsteps:\n  - expect: {Pn101: 99.0}\n")
    r = cli("-q", "run", str(plan), "--yes")
    assert r.code == 3 and "plan FAILED" in r.out
    assert "FAIL unit 1 step 1 (expect, line 4):" in r.err and "Pn101=18 not in" in r.err  # why, though quiet
    (tmp_path / "axis-1.yaml").write_text("taken\n")
    plan.write_text("port: sim\nprofile: dsx7e\nsteps:\n  - backup: axis-{unit}.yaml\n")
    r = cli("-q", "run", str(plan), "--yes")  # refused before the run: the error, though quiet
    assert r.code == 2 and "step 1 (backup, line 4), unit 1:" in r.err and "axis-1.yaml exists" in r.err
