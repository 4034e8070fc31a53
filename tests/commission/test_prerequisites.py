"""A plan's motion steps checked against the drive's settings before anything moves: the drive's values, with the
plan's earlier `set` steps laid over them (virtual time, no real waiting)."""

from __future__ import annotations

from servotool.clock import VirtualClock
from servotool.commission.plan import load_plan
from servotool.commission.prerequisites import unmet
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink


def _drive(pid: str) -> Drive:
    clock = VirtualClock(1000.0)
    profile = load_profile(pid)
    return Drive(VirtualLink([build_drive(profile, 1, clock, persist=False)], clock), profile, 1)


def _plan(tmp_path, pid: str, steps: str):
    path = tmp_path / "plan.yaml"
    path.write_text(f"profile: {pid}\n" + (steps if steps.startswith("units") else f"steps:\n{steps}"))
    return load_plan(path)


def test_a_setting_an_earlier_set_step_writes_counts_and_one_nobody_writes_is_named(tmp_path):
    drive = _drive("sdc")
    plan = _plan(tmp_path, "sdc", "  - jog: {speed: 100, time: 1}\n  - set: {PN4: 3}\n  - jog: {speed: 100, time: 1}\n")
    ((step, refusal),) = unmet(plan, drive)
    assert step.index == 0 and refusal.feature == "JOG"
    assert refusal.settings() == ["PN4 = 3 (now 0)"]
    assert unmet(_plan(tmp_path, "sdc", "  - wait: 1\n"), drive) == []  # no motion step: nothing is read


def test_a_power_cycle_setting_the_plan_writes_is_still_waiting_at_the_motion_step(tmp_path):
    """SD25 Po407 takes effect at the next power-up: a plan that sets it and then jogs would be refused at the JOG."""
    drive = _drive("sd25")
    plan = _plan(tmp_path, "sd25", "  - set: {Po407: 26, Po408: 27, So-58: 1}\n  - jog: {speed: 100, time: 1}\n")
    ((step, refusal),) = unmet(plan, drive)
    assert step.name == "jog"
    assert not refusal.missing and {g.code for g in refusal.waiting} == {"Po407", "Po408"}
    assert "(set, in effect after a power cycle)" in str(refusal)


def test_a_step_on_other_axes_is_not_checked_on_this_one(tmp_path):
    drive = _drive("sdc")
    plan = _plan(tmp_path, "sdc", "units: [1, 2]\nsteps:\n  - jog: {speed: 100, time: 1}\n    unit: 2\n")
    assert unmet(plan, drive) == []
