"""The man page covers every command and option of the real CLI, is current, and groff finds nothing wrong."""

from __future__ import annotations

import importlib.util
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import typer

from servotool.cli.main import app

PAGE = Path(__file__).resolve().parents[2] / "man" / "servotool.1"


def _commands(group, prefix="servotool"):
    yield prefix, group
    for name, cmd in getattr(group, "commands", {}).items():
        yield from _commands(cmd, f"{prefix} {name}")


def _plain(roff: str) -> str:
    return re.sub(r"\\f[BIRP]|\\&", "", roff).replace("\\-", "-")


def test_every_command_and_option_is_in_the_man_page():
    text = _plain(PAGE.read_text())
    missing = []
    for path, cmd in _commands(typer.main.get_command(app)):
        if path != "servotool" and not getattr(cmd, "commands", None) and f".SS {path}" not in text:
            missing.append(path)
        for p in cmd.params:
            for opt in getattr(p, "opts", []):
                if (
                    opt.startswith("-")
                    and p.name not in ("help", "install_completion", "show_completion")
                    and opt not in text
                ):
                    missing.append(f"{path} {opt}")
    assert not missing, f"not in man/servotool.1 (run python man/build.py): {missing}"


def test_man_page_is_generated_from_the_current_cli():
    spec = importlib.util.spec_from_file_location("build", PAGE.with_name("build.py"))
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    strip = lambda t: re.sub(r"^\.TH .*$", "", t, flags=re.M)  # noqa: E731 - the date line changes monthly
    assert strip(build.render()) == strip(PAGE.read_text()), "man page out of date: run python man/build.py"


@pytest.mark.skipif(not shutil.which("groff"), reason="needs groff (installed by .ci/run)")
def test_groff_reports_no_warnings():
    proc = subprocess.run(["groff", "-man", "-ww", "-z", str(PAGE)], capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_every_plan_step_is_documented():
    from servotool.commission.plan import STEP_NAMES, TUNE_KEYS

    text = _plain(PAGE.read_text())
    section = text[text.index(".SH PLAN FILES") : text.index(".SH SHELL COMPLETION")]
    assert all(f"{name}:" in section for name in STEP_NAMES), section
    assert all(f"{key}:" in section for key in TUNE_KEYS), section
