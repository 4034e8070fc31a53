"""Fast start: a one-shot command loads only what it uses (no numpy, pydantic or other commands' modules;
piped, no rich); --help lists the commands without loading one. pydantic comes with typer 0.29, which builds a
pydantic adapter for every option (pyproject holds typer below it)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import atexit, json, sys
def report():
    names = ("numpy", "pydantic", "yaml", "servotool.tuning", "servotool.commission", "servotool.cli.tune",
             "servotool.cli.run", "servotool.cli.jog", "servotool.model.schema", "rich",
             "servotool.cli.messages", "servotool.ops.identity", "servotool.ops.restore", "encodings.idna")
    sys.stderr.write("LOADED " + json.dumps([n for n in names if n in sys.modules]) + "\\n")
atexit.register(report)
sys.argv = ["servotool", *sys.argv[1:]]
from servotool.cli.main import run
run()
"""


def loaded(env: dict[str, str], *args: str, probe: str = PROBE) -> list[str]:
    r = subprocess.run(
        [sys.executable, "-c", probe, *args],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, **env},
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    line = next(x for x in r.stderr.splitlines() if x.startswith("LOADED "))
    return json.loads(line.removeprefix("LOADED "))


def test_param_get_loads_no_numpy_pydantic_yaml_or_other_commands(sim_dir, tmp_path):
    env = {"SERVOTOOL_CACHE_DIR": str(tmp_path / "cache")}
    loaded(env, "--port", "sim", "param", "get", "Pn004")  # the first run compiles the profile
    assert loaded(env, "--port", "sim", "param", "get", "Pn004") == []


def test_param_get_on_a_real_port_loads_no_modbus_library_asyncio_or_file_lock(sim_dir, tmp_path):
    from servotool.model.loader import load_profile
    from servotool.sim.firmware import build_drive
    from servotool.sim.server import EmbeddedSim

    sim = EmbeddedSim([build_drive(load_profile("dsx7e"), 1, persist=False)])  # this process serves the drive
    env = {"SERVOTOOL_CACHE_DIR": str(tmp_path / "cache")}
    names = ("pymodbus", "asyncio", "filelock")
    probe = PROBE.replace('"numpy", ', f'*{names!r}, "numpy", ')
    try:
        args = ("--port", sim.port, "-P", "dsx7e", "param", "get", "Pn004")
        loaded(env, *args)
        assert set(loaded(env, *args, probe=probe)).isdisjoint(names)
        assert set(loaded(env, "--port", "sim", "param", "get", "Pn004", probe=probe)) >= set(names)  # can fail
    finally:
        sim.close()


def test_tune_help_loads_tuning_only_when_asked(sim_dir):
    assert "servotool.tuning" in loaded({}, "tune", "inertia", "--help")


EXIT_PROBE = """
import atexit, sys, threading, time
class Noisy:
    def __del__(self):
        sys.stderr.write("TEARDOWN\\n")
keep = Noisy()                      # a module global: only the interpreter's teardown deletes it
atexit.register(lambda: sys.stderr.write("ATEXIT\\n"))
if "--thread" in sys.argv:
    sys.argv.remove("--thread")
    threading.Thread(target=lambda: (time.sleep(0.3), sys.stderr.write("THREAD DONE\\n"))).start()
sys.argv = ["servotool", *sys.argv[1:]]
from servotool.cli.main import run
run()
"""


def ended(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", EXIT_PROBE, *args], capture_output=True, text=True, cwd=ROOT, timeout=120
    )


def test_a_one_shot_ends_after_its_exit_handlers_without_tearing_the_interpreter_down(sim_dir):
    r = ended("--port", "sim", "param", "get", "Pn004", "--json")
    assert r.returncode == 0 and json.loads(r.stdout)[0]["code"] == "Pn004"
    assert "ATEXIT" in r.stderr and "TEARDOWN" not in r.stderr  # the teardown took ~20 ms
    r = ended("--port", "sim", "param", "get", "Pn999")
    assert r.returncode == 2 and "unknown code" in r.stderr and "ATEXIT" in r.stderr


def test_the_exit_still_waits_for_a_thread_that_is_not_a_daemon(sim_dir):
    r = ended("--thread", "--version")
    assert r.returncode == 0 and "THREAD DONE" in r.stderr and "ATEXIT" in r.stderr


def test_help_lists_the_commands_without_loading_them_rich_or_markdown(sim_dir):
    names = ("servotool.cli.param", "servotool.cli.sim", "servotool.cli.trace", "pygments", "markdown_it")
    probe = PROBE.replace('"numpy", ', f'*{names!r}, "numpy", ')
    assert loaded({}, "--help", probe=probe) == []
