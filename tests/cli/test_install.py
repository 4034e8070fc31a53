"""The built wheel carries every module and the profiles: installed (not editable), run from another directory, it
finds them. The README's first command installs this way; the suite's editable install would hide a missing package."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_installed_wheel_lists_its_profiles_from_another_directory(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, src / name)
    for folder in ("servotool", "profiles"):
        shutil.copytree(ROOT / folder, src / folder, ignore=shutil.ignore_patterns("__pycache__"))
    wheels, target, elsewhere = tmp_path / "wheels", tmp_path / "site", tmp_path / "elsewhere"
    elsewhere.mkdir()
    pip = [sys.executable, "-m", "pip", "-q", "--disable-pip-version-check"]
    subprocess.run([*pip, "wheel", "--no-deps", "-w", str(wheels), str(src)], check=True, capture_output=True)
    (wheel,) = wheels.glob("servotool-*.whl")
    subprocess.run([*pip, "install", "--no-deps", "--target", str(target), str(wheel)], check=True, capture_output=True)
    env = {
        **os.environ,
        "PYTHONPATH": str(target),
        "SERVOTOOL_SIM_DIR": str(tmp_path / "sim"),
        "SERVOTOOL_CONFIG": str(tmp_path / "none.yaml"),
    }
    code = (
        "import servotool, sys; assert servotool.__file__.startswith(sys.argv[1]), servotool.__file__; "
        "from servotool.cli.main import run; sys.argv = ['servotool', 'profiles', 'list', '--json']; run()"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, str(target)], cwd=elsewhere, env=env, capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    assert {"dsx7e", "sd25", "is620p", "sdc"} <= {p["id"] for p in json.loads(proc.stdout)}
    source = {p.relative_to(ROOT).as_posix() for p in (ROOT / "servotool").rglob("*.py")}
    installed = {p.relative_to(target).as_posix() for p in (target / "servotool").rglob("*.py")}
    assert source - installed == set(), "modules the wheel leaves out (pyproject.toml's packages)"
