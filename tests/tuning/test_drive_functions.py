"""The drive's own functions run and judged (issue 34): friction compensation kept where it improves the score, a
change that makes things worse put back, nothing written where nothing could help. The judgement runs on virtual time
(free of host load); what the drive holds is read from the simulated drive's own parameter bank (or, through the
CLI, by pymodbus' own client against `sim serve`), not through servotool."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.codec import eng_to_raw, words_to_raw
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink, make_motion_setup
from servotool.tuning import drive_functions as functions
from servotool.tuning import function_run as use
from servotool.tuning import score as scoring
from tests.ops.plain_client import read_registers


def _virtual(profile_id: str, baud: int = 115200, **machine: float):
    p = load_profile(profile_id)
    clock = VirtualClock(100.0)
    sim = build_drive(p, 1, clock, persist=False)
    make_motion_setup(sim)
    sim.settings.update(noise=0.0005, **machine)
    sim.firmware.reconfigure()
    d = Drive(VirtualLink([sim], clock, baud), p, 1)
    d.dead_man_waived = True  # SDC documents no dead-man; the virtual drive needs no E-stop
    return sim, d, clock


def _held(sim, code: str) -> int:
    return sim.bank.effective_value(code)


@pytest.mark.parametrize(("profile_id", "fwd", "rev"), [("dsx7e", "Pn121", "Pn122"), ("sdc", "PN137", "PN138")])
def test_friction_compensation_on_a_friction_load_improves_the_score_and_is_kept(sim_dir, profile_id, fwd, rev):
    sim, d, clock = _virtual(profile_id, load_ratio=2.0, friction=0.1, viscous=0.0002)
    motion = scoring.motion_for(2.0)
    before = scoring.measure(d, motion, 3, clock)
    trial = functions.friction_trial(d, motion, before, clock)
    assert trial.found["coulomb_fwd"] == pytest.approx(10.0, abs=1.0)  # 10 % of rated torque, and a little viscous
    trial = functions.judged_trial(d, trial, motion, 3, clock=clock)
    assert trial.verdict == "better" and trial.kept, [(x.name, x.verdict) for x in trial.differences]
    figures = {x.name: x for x in trial.differences}
    assert figures["iae"].verdict == "better" and figures["following_error_rms"].verdict == "better"
    assert _held(sim, fwd) == pytest.approx(100, abs=10) and _held(sim, rev) == pytest.approx(100, abs=10)  # 0.1 %
    assert trial.held[fwd] == pytest.approx(_held(sim, fwd) / 10)
    assert not sim.firmware.plant.servo_on  # at rest, servo as found


def test_a_change_that_makes_things_worse_is_put_back(sim_dir):
    """30 % of rated torque 'compensating' a friction the machine does not have kicks every start."""
    sim, d, clock = _virtual("dsx7e", load_ratio=2.0, friction=0.0)
    motion = scoring.motion_for(2.0)
    trial = functions.FunctionTrial("friction", before=scoring.measure(d, motion, 3, clock))
    for code in ("Pn121", "Pn122"):
        trial.changes.append(functions.Change(d.profile.entry(code), 0, 300, "too much"))
    trial = functions.judged_trial(d, trial, motion, 3, clock=clock)
    assert trial.verdict == "worse" and not trial.kept and "written back" in trial.reason
    assert _held(sim, "Pn121") == 0 and _held(sim, "Pn122") == 0
    assert trial.held == {"Pn121": 0.0, "Pn122": 0.0}


def test_nothing_is_written_where_nothing_could_help(sim_dir):
    sim, d, clock = _virtual("dsx7e", load_ratio=2.0, friction=0.0, viscous=0.0)  # nothing to compensate
    motion = scoring.motion_for(2.0)
    trial = functions.friction_trial(d, motion, scoring.measure(d, motion, 2, clock), clock)
    trial = functions.judged_trial(d, trial, motion, 2, clock=clock)
    assert trial.after is None and not trial.kept and "nothing to change" in trial.reason
    assert _held(sim, "Pn121") == 0 and _held(sim, "Pn122") == 0 and _held(sim, "Pn124") == 0
    sim, d, clock = _virtual("is620p", 57600, load_ratio=3.0, resonance_hz=120.0, resonance_damping=0.02)
    before = scoring.measure(d, motion, 2, clock)
    trial = functions.notch_trial(d, before)
    assert not trial.changes and "nothing to notch" in trial.reason and "is visible" in trial.reason
    assert trial.nyquist_hz < 120.0  # the factory line cannot see the resonance: it says so
    assert _held(sim, "H09-18") == 4000


def test_the_dsx7e_viscous_gain_is_set_from_the_damping_and_kept(sim_dir):
    """Pn124 (its unit read as 0.1 % of rated torque at the rated speed, unverified) set from the torque at the test
    speed, with the Coulomb terms, on a machine with strong viscous friction."""
    sim, d, clock = _virtual("dsx7e", load_ratio=2.0, friction=0.05, viscous=0.002)
    motion = scoring.motion_for(2.0)
    trial = use.run_function(d, "friction", scoring.planned(d, motion), 3, clock=clock)
    assert trial.verdict == "better" and trial.kept, [(x.name, x.verdict) for x in trial.differences]
    # 0.002 of rated torque per rad/s at 3000 rpm (314 rad/s) is 63 % of rated torque at the rated speed
    assert _held(sim, "Pn124") == pytest.approx(628, rel=0.1) and trial.held["Pn124"] == _held(sim, "Pn124") / 10


def test_sd25s_own_friction_compensation_is_raised_step_by_step_and_kept(sim_dir):
    """SD25 section 9.6: gains at their factory values, the coefficient Po187 raised (50 %, then 95 %) while each
    step improves the score; the simulated drive's disturbance estimate (a listed extension) does the rest."""
    sim, d, clock = _virtual("sd25", 57600, load_ratio=2.0, friction=0.3)
    trial = use.run_function(d, "friction", scoring.planned(d, scoring.motion_for(2.0)), 2, clock=clock)
    assert trial.verdict == "better" and trial.kept, [(x.name, x.verdict) for x in trial.differences]
    assert {c.entry.code: (c.old, c.new) for c in trial.changes}["Po187"] == (0, 95)
    assert _held(sim, "Po187") == 95 and _held(sim, "Po183") == 1 and trial.held["Po187"] == 95.0
    figures = {x.name: x for x in trial.differences}
    assert figures["following_error_peak"].verdict == "better"


def test_sd25s_compensation_on_a_resonance_that_it_shakes_is_put_back(sim_dir):
    """Too high a gain on a machine with a resonance: the manual's warning (L8042) holds in the simulator too."""
    sim, d, clock = _virtual("sd25", 57600, load_ratio=2.0, friction=0.0, resonance_hz=40.0, resonance_damping=0.01)
    d.write_raw(d.profile.entry("Po184"), 1000)
    trial = use.run_function(d, "friction", scoring.planned(d, scoring.motion_for(2.0)), 2, clock=clock)
    assert not trial.kept and _held(sim, "Po187") == 0 and _held(sim, "Po184") == 1000


@pytest.mark.parametrize(
    ("profile_id", "machine", "setup", "expect"),
    [
        ("dsx7e", ("--friction", "0.1", "--viscous", "0.002"), (), ("Pn121", "Pn122", "Pn124")),
        ("sd25", ("--friction", "0.5"), ("Po407.X=26", "Po408.X=27"), ("Po187",)),
    ],
)
def test_tune_friction_through_the_cli_holds_what_it_says(cli, sim_serve, profile_id, machine, setup, expect):
    """Real time through the CLI on `sim serve` (the factory line raised as tune does); the stored values read by a
    plain Modbus client."""
    cli("-P", profile_id, "sim", "config", "--load-ratio", "2", *machine)
    if setup:  # SD25's JOG route: DI1/DI2 carry JOGU/JOGD after a power cycle
        assert cli("--port", "sim", "-P", profile_id, "param", "set", "--save", *setup).code == 0
        assert cli("--port", "sim", "-P", profile_id, "sim", "reset", "--power-cycle").code == 0
    port = sim_serve("-P", profile_id)
    args = ("--port", port, "-P", profile_id, "tune", "friction", "--yes", "--no-dead-man", "--repeats", "3", "--json")
    r = cli(*args)
    assert r.code == 0, r.err
    data = r.json()
    assert data["function"] == "friction"
    assert data["judged_on"] == ["following_error_rms", "following_error_peak", "iae"]
    assert data["before"]["figures"]["iae"]["unit"] == "rev" and data["comparison"]["verdict"] == data["verdict"]
    # Whether it helps is judged on virtual time above and in bench/drive_functions.py: a busy host samples the
    # score coarser, and a gain inside that resolution is "unchanged", put back (seen once with two test workers
    # beside a CPU burner). Either way the drive holds what the command says.
    assert (data["verdict"], data["kept"]) in {("better", True), ("unchanged", False)}, data["comparison"]
    p = load_profile(profile_id)
    changed = {c["code"] for c in data["changes"] if c["new"]["value"] != c["old"]["value"]}
    assert set(expect) <= changed
    for change in data["changes"]:
        e = p.entry(change["code"])
        held = words_to_raw(e, read_registers(port, e.address, e.words)) * e.scale
        said = change["new" if data["kept"] else "old"]["value"]
        assert held == pytest.approx(said) and data["held"][e.code]["value"] == pytest.approx(held)


def test_the_resonance_finder_states_the_lines_limit(cli):
    r = cli("--port", "sim", "tune", "resonance", "--yes", "--json")
    assert r.code == 0, r.err
    data = r.json()
    assert data["nyquist"]["value"] == pytest.approx(data["sample_rate"]["value"] / 2, rel=0.01)
    assert data["notch"]["frequency"] is None and "maps no torque-command notch" in data["notch"]["reason"]
    r = cli("--port", "sim", "tune", "notch", "--yes")
    assert r.code == 2 and "maps no torque-command notch" in r.err


def _ringing_is620p(resonance_hz: float, gain_hz: float):
    """IS620P at its factory 57600 baud on a two-mass load (ratio 5) whose speed loop at gain_hz overshoots and
    rings on its resonance."""
    sim, d, clock = _virtual("is620p", 57600, load_ratio=5.0, resonance_hz=resonance_hz, resonance_damping=0.02)
    for role, value in (("inertia_ratio", d.profile.param_from_load_ratio(5.0)), ("speed_loop_gain", gain_hz)):
        entry = d.profile.role(role)
        d.write_raw(entry, eng_to_raw(entry, value))
    return sim, d, clock


def test_the_drives_adaptive_notch_removes_a_two_mass_loads_ringing_and_is_kept(sim_dir):
    sim, d, clock = _ringing_is620p(55.0, 50.0)
    motion = scoring.motion_for(2.0)
    before = scoring.measure(d, motion, 3, clock)
    trial = functions.adaptive_notch_trial(d, motion, before, clock)
    assert trial.found == {"resonance": 55.0}  # what the drive set (H09-18), read back
    trial = functions.judged_trial(d, trial, motion, 3, clock=clock)
    assert trial.verdict == "better" and trial.kept, [(x.name, x.verdict) for x in trial.differences]
    figures = {x.name: x for x in trial.differences}
    assert (
        figures["overshoot"].verdict == "better"
        and figures["overshoot"].after.value < 0.75 * figures["overshoot"].before.value
    )
    assert _held(sim, "H09-18") == 55 and _held(sim, "H09-02") == 0  # kept, and the drive no longer adapting


def test_an_adaptive_notch_that_makes_the_response_worse_is_put_back(sim_dir):
    """At 75 Hz under a 40 Hz loop the notch's phase lag costs more overshoot than the resonance did."""
    sim, d, clock = _ringing_is620p(75.0, 40.0)
    motion = scoring.motion_for(2.0)
    trial = functions.adaptive_notch_trial(d, motion, scoring.measure(d, motion, 3, clock), clock)
    trial = functions.judged_trial(d, trial, motion, 3, clock=clock)
    assert trial.verdict == "worse" and not trial.kept and "written back" in trial.reason
    assert _held(sim, "H09-18") == 4000 and _held(sim, "H09-02") == 0 and trial.held == {"H09-18": 4000.0}


def test_the_report_shows_before_and_after_and_the_score_table(cli, tmp_path):
    pytest.importorskip("matplotlib")
    cli("sim", "config", "--load-ratio", "2", "--friction", "0.1")
    folder = tmp_path / "rep"
    r = cli("--port", "sim", "tune", "friction", "--yes", "--repeats", "2", "--report", str(folder))
    assert r.code == 0, r.err
    assert (folder / "response.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (folder / "report.md").read_text()
    assert "| Pn121 |" in text and "| iae |" in text and "Read back: Pn121 = " in text


def test_tune_vibration_says_in_one_line_why_it_cannot_run(cli):
    """SD25's vibration suppression acts only in its position modes or inside its panel-started auto-tune, and
    servotool moves it by JOG: refused with the reason and exit 2, nothing written; a drive without one says so."""
    r = cli("--port", "sim", "-P", "sd25", "tune", "vibration")
    assert r.code == 2 and r.out == ""
    assert r.err.count("\n") == 1 and "NOT RUN" in r.err and "Po240, Po242" in r.err and "position modes" in r.err
    r = cli("--port", "sim", "-P", "is620p", "tune", "vibration")
    assert r.code == 2 and "maps no vibration suppression" in r.err
