"""The plan runner in-process: its steps and report on the clock it is given."""

from __future__ import annotations

import json

from servotool.clock import VirtualClock
from servotool.commission.plan import load_plan
from servotool.commission.runner import Report, Runner
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink


def virtual_runner(tmp_path, steps: str) -> tuple[Runner, VirtualClock]:
    plan_file = tmp_path / "plan.yaml"
    plan_file.write_text(f"profile: dsx7e\nsteps:\n{steps}")
    clock = VirtualClock(5000.0)
    profile = load_profile("dsx7e")
    drive = Drive(VirtualLink([build_drive(profile, 1, clock, persist=False)], clock), profile, 1)
    runner = Runner(
        load_plan(plan_file),
        [drive],
        yes=True,
        continue_on_error=False,
        ask=lambda _u, _q: True,
        log=lambda _line: None,
        clock=clock,
    )
    return runner, clock


def test_a_wait_step_and_the_report_run_on_the_runners_clock(tmp_path, sim_dir):
    runner, clock = virtual_runner(tmp_path, "  - wait: 3600\n  - expect: {Un100: 0}\n")
    report = Report(tmp_path / "r.json", runner, profile="dsx7e", port="virtual", units=[1])
    assert runner.run()  # an hour of virtual time: no real waiting
    data = report.final(True)
    assert clock.now() >= 8600 and runner.results[0].seconds == 3600
    assert data["seconds"] >= 3600 and json.loads((tmp_path / "r.json").read_text())["status"] == "ok"
    assert data["finished"].startswith("1970-01-01") or data["finished"].startswith("1969-12-31")


def test_a_running_report_whose_process_is_gone_reads_as_interrupted(tmp_path, sim_dir):
    import os
    import socket
    import subprocess
    import sys

    from servotool.commission.runner import STALE, read_report

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    path = tmp_path / "plan.report.json"
    report = {"status": "running", "ok": False, "pid": gone.pid, "host": socket.gethostname(), "steps": [{}]}
    path.write_text(json.dumps(report))
    assert read_report(path)["status"] == STALE and read_report(path)["ok"] is False
    path.write_text(json.dumps({**report, "pid": os.getpid()}))  # still under way
    assert read_report(path)["status"] == "running"
    path.write_text(json.dumps({**report, "host": "another-host"}))  # cannot be told from here
    assert read_report(path)["status"] == "running"
    path.write_text(json.dumps(report))
    runner, _clock = virtual_runner(tmp_path, "  - wait: 1\n")
    new = Report(path, runner, profile="dsx7e", port="virtual", units=[1])
    assert new.previous is not None and new.head["previous_run"]["steps_done"] == 1
    data = new.write("running")
    assert data["pid"] == os.getpid() and data["host"] == socket.gethostname()
    assert data["previous_run"]["status"] == STALE
