"""The plan runner in-process: its steps and report on the clock it is given."""

from __future__ import annotations

import json

from servotool.commission.runner import Report


def test_a_wait_step_and_the_report_run_on_the_runners_clock(tmp_path, virtual_plan):
    plan = virtual_plan("  - wait: 3600\n  - expect: {Un100: 0}\n")
    runner, clock = plan.runner, plan.clock
    report = Report(tmp_path / "r.json", runner, profile="dsx7e", port="virtual", units=[1])
    assert runner.run()  # an hour of virtual time: no real waiting
    data = report.final(True)
    assert clock.now() >= 3700 and runner.results[0].seconds == 3600
    assert data["seconds"] >= 3600 and json.loads((tmp_path / "r.json").read_text())["status"] == "ok"
    assert data["finished"].startswith("1970-01-01") or data["finished"].startswith("1969-12-31")


def test_a_running_report_whose_process_is_gone_reads_as_interrupted(tmp_path, virtual_plan):
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
    new = Report(path, virtual_plan("  - wait: 1\n").runner, profile="dsx7e", port="virtual", units=[1])
    assert new.previous is not None and new.head["previous_run"]["steps_done"] == 1
    data = new.write("running")
    assert data["pid"] == os.getpid() and data["host"] == socket.gethostname()
    assert data["previous_run"]["status"] == STALE
