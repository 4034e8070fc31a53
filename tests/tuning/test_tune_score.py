"""tune score on the simulated drive: the test motion scored on virtual time (the judgement free of host load),
through the CLI saved and compared, and refused input."""

from __future__ import annotations

import json

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning import score as scoring


def _virtual(profile_id: str = "dsx7e", baud: int = 115200, **machine: float):
    p = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim = build_drive(p, 1, clock, persist=False)
    make_motion_setup(sim)
    sim.settings.update(machine)
    sim.firmware.reconfigure()
    return sim, Drive(VirtualLink([sim], clock, baud), p, 1), clock


def test_a_mistuned_loop_scores_worse_beyond_the_spread_and_the_axis_ends_where_it_began(sim_dir):
    sim, d, clock = _virtual(load_ratio=5.0, noise=0.001)
    ratio = d.profile.role("inertia_ratio")
    d.write_raw(ratio, 600)  # the true ratio: J_load / J_motor = 5 (DSX7E Pn004 in %, 100 + ratio)
    motion = scoring.motion_for(2.0)
    start = sim.firmware.plant.position_rev
    good = scoring.measure(d, motion, 3, clock)
    d.write_raw(ratio, 100)  # the drive thinks the load is the rotor alone: a sixth of the loop's gain
    bad = scoring.measure(d, motion, 3, clock)
    diffs, overall = scoring.compare(good.score, bad.score)
    assert overall == "worse", [(x.name, x.verdict) for x in diffs]
    assert {x.name: x.verdict for x in diffs}["iae"] == "worse"
    assert good.score.figures["iae"].spread > 0 and good.score.runs == 3
    assert not sim.firmware.plant.servo_on and abs(sim.firmware.plant.position_rev - start) < 0.2
    # the same settings again: unchanged
    again = scoring.measure(d, motion, 3, clock)
    assert scoring.compare(bad.score, again.score)[1] == "unchanged"


def test_score_saves_compares_and_refuses_what_is_not_a_score(cli, tmp_path):
    a = tmp_path / "a.json"
    r = cli("--port", "sim", "tune", "score", "--yes", "--repeats", "2", "--save", str(a), "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["figures"]["iae"]["unit"] == "rev" and data["figures"]["iae"]["resolution"] > 0
    assert data["nyquist"]["value"] == pytest.approx(data["sample_rate"]["value"] / 2, rel=0.01)
    assert json.loads(a.read_text())["format"] == scoring.SCORE_FORMAT
    r = cli("--port", "sim", "tune", "score", "--yes", "--repeats", "2", "--before", str(a), "--json")
    assert r.code == 0, r.err
    assert r.json()["comparison"]["verdict"] in ("unchanged", "better", "worse")
    r = cli("tune", "compare", str(a), str(a))
    assert r.code == 0 and "verdict: UNCHANGED" in r.out
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    r = cli("tune", "compare", str(a), str(bad))
    assert r.code == 2 and "not a score" in r.err and "Traceback" not in r.err
    r = cli("--port", "sim", "tune", "score", "--yes", "--repeats", "0")
    assert r.code == 2 and "--repeats" in r.err
