"""Snapshots fit for version control (issue 35 item 4): deterministic, keyed by the drive, a diff of two showing only
the values that changed; backups written before them still load."""

from __future__ import annotations

import difflib
import shutil
import subprocess

import pytest
import yaml

from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.ops import backup


def snapshot(cli, path, *more: str) -> str:
    r = cli("--port", "sim", "-P", "sd25", "param", "backup", "--snapshot", "-o", str(path), "--force", *more)
    assert r.code == 0, r.err
    return path.read_text()


def test_two_snapshots_of_a_drive_are_identical_and_differ_only_where_a_value_changed(cli, tmp_path):
    first = snapshot(cli, tmp_path / "a.yaml", "--machine", "press-07")
    again = snapshot(cli, tmp_path / "b.yaml", "--machine", "press-07")
    assert first == again  # no time stamp, no tool version: taken twice, the same bytes
    assert cli("--port", "sim", "-P", "sd25", "param", "set", "Po101=40").code == 0
    after = snapshot(cli, tmp_path / "c.yaml", "--machine", "press-07")
    changed = [row for row in difflib.unified_diff(first.splitlines(), after.splitlines(), n=0) if row[:1] in "+-"][2:]
    assert changed == ["-  Po101: 600  # 60.0 Hz", "+  Po101: 400  # 40.0 Hz"]
    head = yaml.safe_load(after)
    assert head["machine"] == "press-07" and head["unit"] == 1 and head["identity"] == {"So-00": "100", "So-46": "100"}
    assert "created" not in head and "checksum" not in head and head["complete"] is True
    profile = load_profile("sd25")
    codes = list(head["values"])
    assert codes == sorted(codes, key=lambda c: profile.entry(c).address)


@pytest.mark.skipif(not shutil.which("git"), reason="needs git")
def test_git_diff_of_two_commits_of_a_snapshot_shows_only_the_parameter(cli, tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()

    def git(*args: str) -> str:
        env_args = ("-c", "user.name=t", "-c", "user.email=t@example.com")
        r = subprocess.run(["git", *env_args, *args], cwd=repo, capture_output=True, text=True, check=True)
        return r.stdout

    git("init", "-q")
    snapshot(cli, repo / "press-07.yaml")
    git("add", ".")
    git("commit", "-qm", "first")
    assert cli("--port", "sim", "-P", "sd25", "param", "set", "Po102=25").code == 0
    snapshot(cli, repo / "press-07.yaml")
    body = [row for row in git("diff", "-U0").splitlines() if row[:1] in "+-" and row[:3] not in ("+++", "---")]
    assert body == ["-  Po102: 500  # 50.0 ms", "+  Po102: 250  # 25.0 ms"]


def test_a_snapshot_loads_as_a_backup_edited_by_hand_but_not_cut_short(cli, tmp_path):
    path = tmp_path / "s.yaml"
    text = snapshot(cli, path)
    profile = load_profile("sd25")
    b = backup.load(path, profile)
    assert b.snapshot and b.values["Po101"] == 600 and b.warnings == []
    path.write_text(text.replace("  Po101: 600  # 60.0 Hz", "  Po101: 450"))  # an engineer's edit in git
    assert backup.load(path, profile).values["Po101"] == 450
    cut = text[: text.index("  Po101:")]
    path.write_text(cut)
    with pytest.raises(UsageError, match="incomplete"):
        backup.load(path, profile)
    path.write_text(text.replace("  Po101: 600  # 60.0 Hz", "  Po101: 99999"))
    with pytest.raises(UsageError, match="outside"):
        backup.load(path, profile)


OLD_BACKUP = """# servotool parameter backup; values are raw register integers, 'display' is for reading only
servotool_backup: 1
profile: sd25
profile_version: '1.0'
model: SD25
unit: 1
created: '2026-05-01T08:00:00+00:00'
tool_version: 0.1.0
identity:
  So-00: '100'
checksum: {checksum}
values:
  Po102: 250
  Po101: 400
display:
  Po102: 25.0 ms
  Po101: 40.0 Hz
"""


def test_a_backup_in_the_format_before_snapshots_still_loads_diffs_and_restores(cli, tmp_path):
    profile = load_profile("sd25")
    values = {"Po102": 250, "Po101": 400}
    checksum = backup.Backup("sd25", "1.0", "SD25", 1, "", "", {}, values).checksum()
    old = tmp_path / "old.yaml"
    old.write_text(OLD_BACKUP.format(checksum=checksum))
    loaded = backup.load(old, profile)
    assert loaded.values == values and loaded.created == "2026-05-01T08:00:00+00:00" and not loaded.snapshot
    sim = ("--port", "sim", "-P", "sd25")

    def differing() -> set[str]:
        r = cli(*sim, "param", "diff", str(old), "--json")
        assert r.code in (0, 1), r.err
        return {x["code"] for x in r.json()["differences"] if x["b"] is not None}

    assert differing() == {"Po101", "Po102"}
    assert cli(*sim, "param", "restore", str(old), "--yes").code == 0
    assert differing() == set()


def test_a_backup_lists_its_values_in_address_order(cli, tmp_path):
    path = tmp_path / "b.yaml"
    assert cli("--port", "sim", "-P", "sdc", "param", "backup", "-o", str(path)).code == 0
    doc = yaml.safe_load(path.read_text())
    profile = load_profile("sdc")
    assert list(doc["values"]) == sorted(doc["values"], key=lambda c: profile.entry(c).address)
    assert list(doc["display"]) == list(doc["values"])
    r = cli("--port", "sim", "-P", "sdc", "param", "backup", "--snapshot", "--format", "csv")
    assert r.code == 2 and "not both" in r.err
    r = cli("--port", "sim", "-P", "sdc", "param", "backup", "--machine", "m1", "-o", str(tmp_path / "c.yaml"))
    assert r.code == 2 and "--snapshot" in r.err
