"""A gain write interrupted during the step check that judges it (issue 29): `tune inertia`'s check after writing
and `tune gains`' search put the previous gains back and say so on the interrupt; a check that only measures says
plainly that what was written stays."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink
from servotool.tuning import gain_search, gain_writes, step, tune

GAIN_CODES = ("Pn101", "Pn102", "Pn100", "Pn128", "Pn003")


def _drive() -> tuple[object, Drive, VirtualClock]:
    profile = load_profile("dsx7e")
    clock = VirtualClock(10.0)
    sim = build_drive(profile, 1, clock, persist=False)
    return sim, Drive(VirtualLink([sim], clock), profile, 1), clock


def _gains(sim) -> dict[str, int]:
    return {code: sim.bank.effective_value(code) for code in GAIN_CODES}


def _interrupted(*_args: object, **_kw: object) -> None:
    raise KeyboardInterrupt


def test_an_interrupted_check_after_writing_the_gains_puts_the_previous_ones_back(sim_dir, monkeypatch):
    sim, d, clock = _drive()
    before = _gains(sim)
    _sugg, changes, _m = gain_writes.gain_changes(d, 3.0, rigidity=16, bandwidth_hz=None)
    for c in changes:
        d.write_raw(c.entry, c.raw)
    assert _gains(sim) != before
    monkeypatch.setattr(step, "step_response", _interrupted)
    with pytest.raises(KeyboardInterrupt) as raised:
        tune.verify_gains(d, changes, tune.TuneRequest(travel_rev=12.0), clock)
    assert _gains(sim) == before
    assert any("previous gains were written back" in note for note in raised.value.__notes__)


def test_an_interrupted_gain_search_puts_the_gains_before_it_back(sim_dir, monkeypatch):
    sim, d, clock = _drive()
    before = _gains(sim)
    calls = {"n": 0}
    real = step.step_response

    def second_level_interrupted(*args: object, **kw: object) -> step.StepResponse:
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt  # Ctrl-C during the second level's check, its gains written
        return real(*args, **kw)

    monkeypatch.setattr(step, "step_response", second_level_interrupted)
    with pytest.raises(KeyboardInterrupt) as raised:
        gain_search.search_gains(d, load_ratio=2.0, travel_rev=12.0, clock=clock)
    assert calls["n"] == 2
    assert _gains(sim) == before
    assert any("gains before it were written back" in note for note in raised.value.__notes__)


def test_the_cli_says_the_previous_gains_are_back_and_ends_with_the_stop(sim_dir, tmp_path):
    """Through the CLI's own exit path (typer turns Ctrl-C into exit 130): the note, then 'interrupted', then the
    stop's line."""
    import subprocess
    import sys

    script = tmp_path / "interrupted.py"
    script.write_text(
        "import sys\n"
        "import servotool.tuning.step as step\n"
        "def interrupted(*a, **k):\n"
        "    raise KeyboardInterrupt\n"
        "step.step_response = interrupted\n"
        "sys.argv = ['servotool', '--port', 'sim', 'tune', 'inertia', '--yes', '--rigidity', '14', '--travel', '12']\n"
        "from servotool.cli.main import run\n"
        "run()\n"
    )
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 130, r.stderr
    lines: list[str] = []  # each "servotool:" message with the lines it wraps onto at 80 columns
    for line in r.stderr.splitlines():
        if line.startswith("servotool:"):
            lines.append(line)
        elif lines and line:
            lines[-1] += " " + line
    assert "the previous gains were written back (Pn101 18.0" in " ".join(lines[-3].split()), r.stderr
    assert lines[-2] == "servotool: interrupted" and lines[-1].startswith("servotool: stopped, servo off")
