"""A plan's tune step writes the same report folder as `tune inertia --report`."""

from __future__ import annotations

import pytest

from tests.tuning.realtime_cli import run_plan


def test_a_tune_step_writes_its_report_beside_the_plan(cli, tmp_path):
    pytest.importorskip("matplotlib")
    plan = tmp_path / "plan.yaml"
    plan.write_text(
        "port: sim\nsteps:\n  - tune inertia: {rigidity: 12, max_speed: 600, travel: 12, report: 'tune-{unit}'}\n"
    )
    r = cli("run", str(plan), "--dry-run")
    assert r.code == 0 and "report to tune-{unit}" in r.out, r.err
    r = run_plan(cli, str(plan), "--yes", "--json")
    assert r.code == 0, r.err
    step = r.json()["steps"][0]
    folder = tmp_path / "tune-1"
    assert step["report"] == str(folder / "report.md")
    for name in ("motion.png", "fit.png", "moves.png", "gains.png"):
        assert (folder / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
    assert "![Gains](gains.png)" in (folder / "report.md").read_text()


def test_a_report_that_is_not_a_folder_name_is_refused_before_anything_runs(cli, tmp_path):
    plan = tmp_path / "plan.yaml"
    plan.write_text("port: sim\nsteps:\n  - tune inertia: {report: 5}\n")
    r = cli("run", str(plan), "--dry-run")
    assert r.code == 2 and "report must be a folder name" in r.err
