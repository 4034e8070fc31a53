"""`servotool shell` (issue 33 item 5): one open port, the command line's commands at a prompt, in a real terminal
(tmux): a parameter read, a code completed with Tab, a JOG stopped by Ctrl-C with the shell still there, the status
line, the history, and Ctrl-D to leave. The motion is judged by a plain Modbus client on the simulator's port."""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
import time

import pytest
import typer
from pymodbus import FramerType
from pymodbus.client import ModbusTcpClient

from servotool.cli.main import app
from servotool.cli.shell_complete import candidates
from servotool.model.codec import raw_to_eng, words_to_raw
from servotool.model.loader import load_profile
from tests.conftest import ROOT
from tests.terminal import Terminal


def _speed_rpm(port: str) -> float:
    """DSX7E's speed feedback (Un000) read by pymodbus' client, not by servotool."""
    entry = load_profile("dsx7e").entry("Un000")
    host, _, number = port.removeprefix("tcp://").rpartition(":")
    client = ModbusTcpClient(host, port=int(number), framer=FramerType.RTU, timeout=2)
    try:
        assert client.connect()
        reply = client.read_holding_registers(entry.address, count=entry.words, device_id=1)
        assert not reply.isError(), reply
        return float(raw_to_eng(entry, words_to_raw(entry, reply.registers)))
    finally:
        client.close()


def test_a_session_in_a_terminal(sim_dir, sim_serve, tmp_path):
    if not shutil.which("tmux"):
        pytest.skip("needs tmux (installed by .ci/run)")
    port = sim_serve("-P", "dsx7e")
    state = tmp_path / "state"
    ended = tmp_path / "ended"
    env = {
        "SERVOTOOL_SIM_DIR": sim_dir,
        "SERVOTOOL_CONFIG": os.environ["SERVOTOOL_CONFIG"],
        "SERVOTOOL_BACKUP_DIR": os.environ["SERVOTOOL_BACKUP_DIR"],
        "XDG_STATE_HOME": state,
    }
    exports = " ".join(f"{k}={v}" for k, v in env.items())
    command = (
        f"cd {ROOT} && {exports} {sys.executable} -m servotool --port {port} -P dsx7e shell; echo exit $? > {ended}"
    )
    term = Terminal(command, tmp_path)
    try:
        term.wait_for("servotool>")
        term.wait_for("servo off")  # the status line, read while the prompt waits
        term.type("param get Pn101")
        term.keys("Enter")
        term.wait_for("Speed loop gain")

        term.type("param get Pn62")  # one code starts so: Tab completes it
        term.keys("Tab")
        term.wait_for("param get Pn620")
        term.keys("Enter")
        term.wait_for("Host communication watchdog")

        term.type("jog --speed 300 --time 60 --yes")
        term.keys("Enter")
        term.wait_for("speed=")
        deadline, seen = time.monotonic() + 10, 0.0
        while abs(seen) < 250 and time.monotonic() < deadline:
            time.sleep(0.1)
            seen = _speed_rpm(port)
        assert 250 <= seen <= 400  # it runs (forward; a speed loop may overshoot its 300 rpm on the way)
        term.keys("C-c")
        term.wait_for("servotool: stopped, servo off")  # the stop sequence's last line: what it read back
        term.wait_for("servotool>", count=4)  # the prompt again: still in the shell
        deadline = time.monotonic() + 5
        while abs(_speed_rpm(port)) > 10 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert abs(_speed_rpm(port)) <= 10  # stopped, as the drive itself says

        term.type("param get Pn101")
        term.keys("Enter")
        term.wait_for("Speed loop gain", count=2)
        term.wait_for_bottom("│ speed ")  # the status line at the bottom again, once the output is written

        term.keys("C-d")
        deadline = time.monotonic() + 15
        while not ended.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        term.close()
    assert ended.read_text().strip() == "exit 0"
    history = (state / "servotool" / "shell-history").read_text()
    assert "+param get Pn101" in history and "+jog --speed 300 --time 60 --yes" in history


@pytest.fixture
def root():
    return typer.main.get_command(app)


def test_completion_offers_commands_options_codes_and_names(sim_dir, root):
    dsx7e = ["--profile", "dsx7e"]
    assert candidates(root, dsx7e, [], "pa") == [("param", "")]
    assert ("set", "") in candidates(root, dsx7e, ["param"], "")
    assert [v for v, _ in candidates(root, dsx7e, ["param", "get"], "Pn10")][:2] == ["Pn100", "Pn101"]
    assert ("Pn004", "Load inertia ratio") in candidates(root, dsx7e, ["param", "get"], "inertia")  # by name
    assert ("Pn101=", "Speed loop gain") in candidates(root, dsx7e, ["-v", "param", "set"], "Pn10")
    assert [v for v, _ in candidates(root, dsx7e, ["jog"], "--sp")] == ["--speed"]
    assert candidates(root, ["--profile", "sd25"], ["param", "get"], "Po01")[0][0] == "Po010"


def test_lines_from_a_pipe_run_in_turn_on_one_open_port(cli, tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text("port: sim\nsteps:\n  - expect: {Pn101: 20.0}\n")
    script = "\n".join(
        [
            "param set Pn101=20",
            f"run {plan} --yes",  # a plan on the shell's port, not a second simulator
            "-v param get Pn101",  # the frames of a typed -v
            "--port /dev/ttyS9 param get Pn101",  # another port: refused, the shell goes on
            "-u 2 param get Pn101",  # a unit the simulator does not serve
            "shell",
            "param get Pn101 --json",
        ]
    )
    r = cli("--port", "sim", "shell", input=script + "\n")
    assert r.code == 0, r.err
    assert r.err.count("SIMULATED") == 1  # one simulator, one port, for every line
    assert "the shell keeps sim open" in r.err and "unit 1, not 2" in r.err and "already in the shell" in r.err
    # Pn101 = 20.0 Hz, read under -v: alone, or with Pn102 where it repeats the plan's read within the link's copy
    # window (its reply then differs in length from the one before: link/exchange.py)
    assert re.search(r"^>> 01 03 21 01 00 0[12] .*\n<< 01 03 0[24] 00 c8 ", r.err, re.M), r.err
    assert "plan completed: 1/1 steps ok" in r.out
    assert r.out.rstrip().endswith("]") and '"value": 20.0' in r.out


def test_the_status_line_reads_only_while_the_prompt_waits():
    """The line has one master: a status read under way when a command starts is waited for, and none starts
    while the command runs."""
    from servotool.cli.shell import StatusLine

    reads: list[tuple[float, float]] = []

    def read() -> str:
        start = time.monotonic()
        time.sleep(0.05)
        reads.append((start, time.monotonic()))
        return f"read {len(reads)}"

    status = StatusLine(read, every_s=0.01)
    status.start()
    commands: list[tuple[float, float]] = []
    try:
        for _ in range(5):
            with status.reading():
                time.sleep(0.12)
            start = time.monotonic()  # a command runs: the line is its own
            time.sleep(0.1)
            commands.append((start, time.monotonic()))
    finally:
        status.close()
    assert reads and status.text.startswith("read ")
    for c0, c1 in commands:
        assert all(r1 <= c0 or r0 >= c1 for r0, r1 in reads), (commands, reads)


def test_a_json_error_after_a_json_result_in_the_shell_is_a_json_object_too(cli):
    r = cli("--port", "sim", "shell", input="param get Pn101 --json\nparam get Pn999 --json\n")
    first, _, second = r.out.partition("\n]\n")
    assert json.loads(first + "\n]")[0]["code"] == "Pn101"
    assert json.loads(second)["error"]["code"] == "unknown_name", r.out
