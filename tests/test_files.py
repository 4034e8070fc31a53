"""servotool.files: user folders, atomic writes, one YAML error format for every file kind, a lock between processes."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from servotool import files
from servotool.commission.plan import load_plan
from servotool.connection import ConnectOptions, resolve
from servotool.errors import UsageError
from servotool.model.loader import load_profile, read_profile
from servotool.ops.backup import load as load_backup

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(sys.platform != "linux", reason="XDG variables apply on Linux")
def test_folders_follow_xdg_on_linux_and_the_servotool_variables_win(tmp_path, monkeypatch):
    for var in ("SERVOTOOL_CONFIG", "SERVOTOOL_SIM_DIR", "SERVOTOOL_BACKUP_DIR"):
        monkeypatch.delenv(var, raising=False)
    for var in ("XDG_CONFIG_HOME", "XDG_STATE_HOME", "XDG_DATA_HOME"):
        monkeypatch.setenv(var, str(tmp_path / var))
    assert files.config_file() == tmp_path / "XDG_CONFIG_HOME" / "servotool" / "config.yaml"
    assert files.sim_state_dir() == tmp_path / "XDG_STATE_HOME" / "servotool" / "sim"
    assert files.backup_dir() == tmp_path / "XDG_DATA_HOME" / "servotool" / "backups"
    monkeypatch.setenv("SERVOTOOL_CONFIG", str(tmp_path / "c.yaml"))
    monkeypatch.setenv("SERVOTOOL_SIM_DIR", str(tmp_path / "s"))
    monkeypatch.setenv("SERVOTOOL_BACKUP_DIR", str(tmp_path / "b"))
    assert (files.config_file(), files.sim_state_dir(), files.backup_dir()) == (
        tmp_path / "c.yaml",
        tmp_path / "s",
        tmp_path / "b",
    )


def test_an_atomic_write_replaces_only_when_allowed_and_leaves_no_temporary_file(tmp_path):
    path = tmp_path / "new" / "file.txt"
    files.write_atomic(path, "one\n")
    assert path.read_text() == "one\n"
    with pytest.raises(FileExistsError):
        files.write_atomic(path, "two\n", replace=False)
    assert path.read_text() == "one\n"
    files.write_atomic(path, "three\n", durable=False)
    assert path.read_text() == "three\n"
    assert [p.name for p in path.parent.iterdir()] == ["file.txt"]
    if os.name == "posix":
        assert path.stat().st_mode & 0o777 == 0o600  # private, as mkstemp makes it


@pytest.mark.skipif(os.name != "posix", reason="a terminal device by path")
def test_an_atomic_write_to_a_device_writes_through_it_and_leaves_the_device(tmp_path):
    """`param backup -o /dev/null --force` as root once renamed a regular file over /dev/null: a device (here a
    terminal, as harmless to write) is written through, and stays a device."""
    import stat

    master, slave = os.openpty()
    try:
        device = Path(os.ttyname(slave))
        files.write_atomic(device, b"through\n")
        assert stat.S_ISCHR(device.stat().st_mode)
        assert os.read(master, 100).replace(b"\r", b"") == b"through\n"
        with pytest.raises(FileExistsError):
            files.write_atomic(device, b"again\n", replace=False)
        assert not list(device.parent.glob(f".{device.name}.*"))  # no temporary file beside it
    finally:
        os.close(master)
        os.close(slave)


BROKEN = "a: [1, 2\nb: 3\n"


def _messages(tmp_path: Path, monkeypatch) -> list[str]:
    """What each kind of file says about the same broken YAML."""
    path = tmp_path / "mini.yaml"
    path.write_text(BROKEN)
    said = [read_profile(path)[1][0]]
    for read in (
        lambda: load_backup(path, load_profile("dsx7e")),
        lambda: load_plan(path),
        lambda: resolve(ConnectOptions(port="sim")),
    ):
        monkeypatch.setenv("SERVOTOOL_CONFIG", str(path))
        with pytest.raises(UsageError) as exc:
            read()
        said.append(str(exc.value))
    return said


def test_every_file_kind_reports_broken_yaml_the_same_way(tmp_path, monkeypatch):
    said = _messages(tmp_path, monkeypatch)
    assert len(set(said)) == 1, said
    assert said[0].startswith(f"{tmp_path / 'mini.yaml'}: line 2: invalid YAML: ")


def test_every_file_kind_reports_bytes_that_are_not_utf8_the_same_way(tmp_path, monkeypatch):
    path = tmp_path / "mini.yaml"
    path.write_bytes(b"model: caf\xe9\n")
    said = {read_profile(path)[1][0]}
    for read in (lambda: load_backup(path, load_profile("dsx7e")), lambda: load_plan(path)):
        with pytest.raises(UsageError) as exc:
            read()
        said.add(str(exc.value))
    assert said == {f"{path}: not UTF-8 text (byte 10)"}


def test_a_lock_held_by_another_process_is_waited_for(tmp_path):
    lock = tmp_path / "state" / "drive.lock"
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time\nfrom pathlib import Path\nfrom servotool.files import FileLock\n"
            "with FileLock(Path(sys.argv[1])).held():\n    print('held', flush=True)\n    time.sleep(0.5)\n",
            str(lock),
        ],
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert holder.stdout is not None and holder.stdout.readline() == "held\n"
        start = time.monotonic()
        with files.FileLock(lock).held():
            waited = time.monotonic() - start
        assert waited > 0.2
    finally:
        holder.wait(5)
    start = time.monotonic()
    with files.FileLock(lock).held():
        assert time.monotonic() - start < 0.2  # free again once the holder has gone
