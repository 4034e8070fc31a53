"""`servotool trace`, `plot`, `monitor --plot` and `jog --trace` as a user runs them (through the embedded
simulator); bad input is refused in one line before the port opens."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from servotool.ops.trace_file import read_table

ROOT = Path(__file__).resolve().parents[2]
NO_PORT = ("--port", "/dev/nonexistent", "--profile", "dsx7e")


def test_a_free_running_trace_writes_a_csv_with_units_and_line_settings(cli, tmp_path):
    out = tmp_path / "t.csv"
    r = cli("--port", "sim", "trace", "Un000", "Un002", "--samples", "30", "-o", str(out))
    assert r.code == 0, r.err
    assert "capture 1: 30 samples" in r.err and "samples/s, jitter" in r.err
    table = read_table(out)
    assert [s.label for s in table.series] == ["Un000 [rpm]", "Un002 [%]"] and len(table.t) == 30
    assert any(a.startswith("line: sim, 115200 8N1") for a in table.about)
    assert any("1 request(s) per sample" in a for a in table.about)
    png = tmp_path / "t.png"
    r = cli("plot", str(out), "-o", str(png))
    assert r.code == 0, r.err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    r = cli("plot", str(out), "--column", "Un002")
    assert r.code == 0 and "Un002 [%]" in r.out and "Un000" not in r.out


def test_a_trace_as_json_and_a_trigger_that_never_fires(cli):
    r = cli("--port", "sim", "trace", "Un000", "-n", "5", "--json")
    assert r.code == 0, r.err
    cap = r.json()["captures"][0]
    assert cap["samples"] == 5 and cap["values"]["Un000"]["unit"] == "rpm" and cap["rate"]["value"] > 0
    assert all(type(v) is int for v in cap["values"]["Un000"]["values"])  # rpm in steps of 1: -2, not -2.0
    r = cli("--port", "sim", "trace", "Un000", "--trigger", "Un000>1000", "--timeout", "0.3")
    assert r.code == 1 and "the trigger did not fire within --timeout; Un000 ranged" in r.err
    assert "Traceback" not in r.err


@pytest.mark.parametrize(
    "args, message",
    [
        (("trace", "--trigger", "Un000=3"), "bad --trigger"),
        (("trace", "--pre", "100"), "0..99 %"),
        (("trace", "--samples", "10", "--duration", "1"), "not both"),
        (("trace", "--repeat", "-1"), "bad --repeat"),
        (("trace", "Pn999"), "Pn999"),
    ],
)
def test_bad_trace_options_fail_before_the_port_opens(cli, args, message):
    r = cli(*NO_PORT, *args)
    assert r.code == 2 and message in r.err and len(r.err.strip().splitlines()) == 1, r.err


def test_plot_refuses_what_is_not_a_trace(cli, tmp_path):
    bad = tmp_path / "x.csv"
    bad.write_text("a,b\n1,2\n")
    r = cli("plot", str(bad))
    assert r.code == 2 and "no time column" in r.err
    r = cli("plot", str(tmp_path / "missing.csv"))
    assert r.code != 0 and "missing.csv" in r.err and "Traceback" not in r.err


def test_monitor_plot_falls_back_to_plain_lines_when_not_a_terminal(cli):
    r = cli("--port", "sim", "monitor", "Un000", "Un002", "--plot", "--rate", "50", "--duration", "0.2")
    assert r.code == 0, r.err
    lines = r.out.strip().splitlines()
    assert len(lines) >= 3 and all(" s  Un000 " in line and " rpm  Un002 " in line for line in lines)


def test_jog_trace_records_its_own_motion_on_the_same_port(cli, tmp_path):
    out = tmp_path / "jog.csv"
    r = cli("--port", "sim", "jog", "--speed", "300", "--time", "0.6", "--trace", str(out), "--json")
    assert r.code == 0, r.err
    table = read_table(out)
    speed = next(s for s in table.series if s.label == "Un000 [rpm]")
    assert max(speed.values) > 250 and abs(speed.values[-1]) < 20  # it ran and stopped
    # The JOG's own peak is its trace's (issue 33: it said 603 rpm where a trace beside it saw 669).
    assert len(table.t) > 20 and json.loads(r.out)["peak_speed"]["value"] == max(abs(v) for v in speed.values)
    position = next(s for s in table.series if s.name == "Un012")
    assert position.values[-1] > position.values[0]  # exact counts, moving forward


def test_tune_report_is_refused_before_anything_moves_where_it_cannot_be_written(cli, tmp_path):
    """(The report itself is drawn by tests/report on virtual time and by a plan's tune step.)"""
    (tmp_path / "file").write_text("")
    r = cli(*NO_PORT, "tune", "inertia", "--report", str(tmp_path / "file"))
    assert r.code == 2 and "it is a file" in r.err


def test_the_monitor_chart_is_readable_at_80_columns_with_every_entry_in_a_legend(sim_dir):
    from collections import deque

    from rich.console import Console

    from servotool.cli.monitor import monitor_chart
    from servotool.connection import ConnectOptions, resolve
    from servotool.ops.monitor import Monitor
    from servotool.session import open_drives

    with open_drives(resolve(ConnectOptions(port="sim", profile="dsx7e")), notice=lambda _m: None) as (d,):
        mon = Monitor(d, [d.profile.entry(c) for c in ("Un000", "Un001", "Un002")])
        history = deque(mon.run(1000, None, samples=30))
    console = Console(width=80, record=True, force_terminal=True, color_system=None)
    console.print(monitor_chart(mon, history, 80, 30))
    lines = console.export_text().splitlines()
    assert max(len(line) for line in lines) <= 80
    text = "\n".join(lines)
    for label in ("Un000 [rpm]", "Un001 [rpm]", "Un002 [%]"):
        assert label in text
    assert "30 samples" in lines[0] and "not drawn" not in text  # title; two units fit in 30 rows


def test_ctrl_c_writes_the_captures_taken_and_exits_130(sim_dir):
    proc = subprocess.Popen(
        [sys.executable, "-m", "servotool", "--port", "sim", "trace", "Un000", "--samples", "20", "--repeat", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        while "capture 1:" not in proc.stderr.readline():  # one capture taken (--repeat 0: until Ctrl-C)
            assert proc.poll() is None
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "servotool: interrupted" in err and "did not fire" not in err
    assert out.startswith("# servotool trace") and "Un000" in out
