"""The files a plan names: resolved against its folder and kept inside it, existing ones replaced only when the plan,
the step or --force says so, every one listed and checked before anything moves (issue 30 item 10, issue 33 item 1).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from servotool.commission.plan import load_plan
from servotool.commission.plan_files import resolve
from servotool.commission.steps import validate
from servotool.errors import UsageError
from servotool.model.loader import load_profile

ROOT = Path(__file__).resolve().parents[2]


def _plan(folder: Path, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "plan.yaml"
    path.write_text("port: sim\nprofile: dsx7e\n" + text)
    return path


def _check(path: Path, units: list[int] | None = None, *, force: bool = False):
    return validate(load_plan(path), load_profile("dsx7e"), units, force=force)


def test_a_name_that_leaves_the_plans_folder_is_refused_unless_the_plan_allows_it(tmp_path):
    """Issue 30: `backup: {file: ../../x, overwrite: true}` replaced an unrelated file."""
    unrelated = tmp_path / "x"
    unrelated.write_text("someone else's\n")
    plan = _plan(tmp_path / "a" / "b", "steps:\n  - backup: {file: ../../x, overwrite: true}\n")
    with pytest.raises(UsageError, match=r"outside the plan's folder .*allow_outside: true"):
        _check(plan)
    plan.write_text(plan.read_text().replace("steps:", "allow_outside: true\nsteps:"))
    (found,) = _check(plan).files
    assert found.path.resolve() == unrelated and found.exists


def test_an_absolute_name_and_a_symbolic_link_out_of_the_folder_are_outside_too(tmp_path):
    plan = _plan(tmp_path / "p", f"steps:\n  - backup: {tmp_path / 'elsewhere.yaml'}\n")
    with pytest.raises(UsageError, match="outside the plan's folder"):
        _check(plan)
    if os.name == "posix":
        (tmp_path / "p" / "link").symlink_to(tmp_path)
        plan.write_text("port: sim\nsteps:\n  - backup: link/axis.yaml\n")
        with pytest.raises(UsageError, match="outside the plan's folder"):
            _check(plan)
    plan.write_text(f"port: sim\nsteps:\n  - backup: {tmp_path / 'p' / 'inside.yaml'}\n")
    assert _check(plan).files[0].path == tmp_path / "p" / "inside.yaml"


def test_a_tilde_is_the_home_folder_not_a_folder_named_tilde(tmp_path, monkeypatch):
    """Issue 30: `~` became a folder named `~`."""
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setenv("USERPROFILE", str(tmp_path / "home"))
    plan = load_plan(_plan(tmp_path / "p", "allow_outside: true\nsteps:\n  - backup: ~/axis-{unit}.yaml\n"))
    assert resolve(plan, "~/axis-{unit}.yaml", 2, several=False) == tmp_path / "home" / "axis-2.yaml"
    plan.allow_outside = False
    with pytest.raises(UsageError, match="outside the plan's folder"):
        resolve(plan, "~/axis.yaml", 1, several=False)


def test_existing_files_need_overwrite_in_the_step_or_the_plan_or_force(tmp_path):
    plan = _plan(tmp_path, "units: [1, 2]\nsteps:\n  - backup: axis-{unit}.yaml\n")
    for unit in (1, 2):
        (tmp_path / f"axis-{unit}.yaml").write_text("kept\n")
    with pytest.raises(UsageError) as refused:
        _check(plan)
    assert "2 problems" in str(refused.value)  # each axis' file, in one line
    assert "unit 1: " in str(refused.value) and "unit 2: " in str(refused.value)
    assert "say 'overwrite: true' (in the step or the plan) or pass --force" in str(refused.value)
    assert all(f.overwrite and f.exists for f in _check(plan, force=True).files)
    plan.write_text(plan.read_text().replace("units:", "overwrite: true\nunits:"))
    assert len(_check(plan).files) == 2
    plan.write_text("port: sim\nunits: [1, 2]\nsteps:\n  - backup: {file: 'axis-{unit}.yaml', overwrite: true}\n")
    assert len(_check(plan).files) == 2
    plan.write_text("port: sim\noverwrite: yes please\nsteps:\n  - wait: 1\n")
    with pytest.raises(UsageError, match="overwrite must be true or false"):
        load_plan(plan)


def test_one_file_written_twice_and_a_restore_of_a_missing_file_are_refused(tmp_path):
    plan = _plan(
        tmp_path,
        "steps:\n  - restore: before.yaml\n  - backup: axis.yaml\n  - backup: axis.yaml\n  - restore: axis.yaml\n",
    )
    with pytest.raises(UsageError) as refused:
        _check(plan)
    text = str(refused.value)
    assert "2 problems" in text, text
    assert "step 1 (restore, line 4), unit 1: " in text and "before.yaml does not exist" in text
    assert "step 3 (backup, line 6), unit 1: " in text and "is written already by step 2" in text
    (tmp_path / "before.yaml").write_text("")
    plan.write_text(plan.read_text().replace("  - backup: axis.yaml\n  - backup", "  - backup"))
    kinds = [(f.kind, f.writes) for f in _check(plan).files]  # the restore of axis.yaml follows its backup
    assert kinds == [("restore", False), ("backup", True), ("restore", False)]


def test_a_tune_report_folder_with_files_in_it_needs_overwrite(tmp_path):
    pytest.importorskip("matplotlib")
    plan = _plan(tmp_path, "steps:\n  - tune inertia: {report: 'tune-{unit}'}\n")
    assert _check(plan).files[0].path == tmp_path / "tune-1"
    (tmp_path / "tune-1").mkdir()
    assert not _check(plan).files[0].exists  # an empty folder holds nothing to lose
    (tmp_path / "tune-1" / "report.md").write_text("last week's\n")
    with pytest.raises(UsageError, match="tune-1 has files in it"):
        _check(plan)


def test_the_dry_run_lists_every_file_and_refuses_what_the_run_would_fail_on(cli, tmp_path, sim_dir):
    plan = _plan(
        tmp_path,
        "units: [1, 2]\nsteps:\n  - set: {Pn101: 25.0}\n  - backup: axis-{unit}.yaml\n  - restore: axis-{unit}.yaml\n",
    )
    r = cli("run", str(plan), "--dry-run")
    assert r.code == 0, r.err
    listed = r.out[r.out.index("Would write:") :].splitlines()
    assert listed[1] == f"  an automatic backup of unit(s) 1, 2 into {sim_dir.parent / 'auto-backups'}/"
    assert listed[2:5] == [
        f"  {tmp_path / 'axis-1.yaml'} (backup, step 2, unit 1)",
        f"  {tmp_path / 'axis-2.yaml'} (backup, step 2, unit 2)",
        f"  {tmp_path / 'plan.report.json'} (the run's report)",
    ]
    assert listed[5] == f"Would read: {tmp_path / 'axis-1.yaml'} (restore, step 3, unit 1)"
    data = cli("run", str(plan), "--dry-run", "--json").json()
    assert [(f["kind"], f["unit"], f["replaces"]) for f in data["files"]] == [
        ("backup", 1, False),
        ("backup", 2, False),
        ("restore", 1, False),
        ("restore", 2, False),
    ]
    assert data["report"] == str(tmp_path / "plan.report.json") and data["auto_backups"]["units"] == [1, 2]
    (tmp_path / "axis-2.yaml").write_text("kept\n")
    for args in (("--dry-run",), ("--yes",)):  # the real run stops at the same check, before anything is written
        r = cli("-v", "run", str(plan), *args)
        assert r.code == 2 and "axis-2.yaml exists" in r.err and "overwrite: true" in r.err, r.err
        assert ">> 01 10" not in r.err and ">> 01 06" not in r.err
    assert (tmp_path / "axis-2.yaml").read_text() == "kept\n" and not (tmp_path / "plan.report.json").exists()
    assert not (sim_dir.parent / "auto-backups").exists()
    assert cli("--port", "sim", "param", "get", "Pn101", "--json").json()[0]["value"] == 18.0


def test_run_report_replaces_a_plan_report_but_another_file_only_with_force(cli, tmp_path):
    """Issue 30: `run --report FILE` overwrote any file."""
    plan = _plan(tmp_path, "steps:\n  - expect: {Un100: 0}\n")
    notes = tmp_path / "notes.txt"
    notes.write_text("not a report\n")
    r = cli("run", str(plan), "--report", str(notes))
    assert r.code == 2 and "notes.txt exists and is not a plan report; pass --force" in r.err, r.err
    assert notes.read_text() == "not a report\n"
    assert cli("run", str(plan), "--report", str(notes), "--force").code == 0
    assert json.loads(notes.read_text())["status"] == "ok"
    assert cli("run", str(plan), "--report", str(notes)).code == 0  # a plan report now: replaced by each run


def test_the_readme_example_plan_can_run_again_with_its_last_runs_files_in_place(cli, tmp_path):
    """Issue 33: every run after the first exited 2 at the backup step ('commissioned-1.yaml exists') after both
    axes had moved, while the dry run called the plan valid. The example's backup says overwrite: true, and the
    check every run makes first (the dry run's) passes with a previous run's files in place. (That the example's
    identification passes run after run, idle and loaded, is measured by bench/example_plan.py: real time.)"""
    folder = tmp_path / "examples"
    shutil.copytree(ROOT / "examples", folder)
    plan = folder / "commission.yaml"
    r = cli("run", str(plan), "--dry-run", "--json")
    assert r.code == 0, r.err
    assert [(f["kind"], f["path"], f["replaces"]) for f in r.json()["files"]] == [
        ("backup", str(folder / "commissioned-1.yaml"), False),
        ("backup", str(folder / "commissioned-2.yaml"), False),
    ]
    for unit in (1, 2):  # what the first run left
        (folder / f"commissioned-{unit}.yaml").write_text("servotool_backup: 1\n")
    (folder / "commission.report.json").write_text('{"status": "ok", "plan": "x", "steps": []}')
    r = cli("run", str(plan), "--dry-run", "--json")
    assert r.code == 0, r.err
    assert [f["replaces"] for f in r.json()["files"]] == [True, True]
    plan.write_text(plan.read_text().replace(", overwrite: true", ""))
    with pytest.raises(UsageError, match=r"commissioned-1\.yaml exists"):  # what the example met without it
        _check(plan)
