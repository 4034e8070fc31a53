"""The drive settings a plan's motion steps need (the profile's motion_setup), checked on the drives before anything
moves: what each drive holds, with the values the plan's earlier `set` steps write laid over it.

Without it a plan could write its parameters, tune one axis, and only then stop at a JOG that the drive is not set
up for; now that refusal comes first, naming the step, the axis and the settings.
"""

from __future__ import annotations

from servotool.commission.param_steps import SetStep
from servotool.commission.plan import Plan, Step
from servotool.drive import Drive
from servotool.errors import SetupRequired
from servotool.model.profile import Profile
from servotool.model.setup import Requirement, requirements, setup_required

# step -> the feature named in the refusal
MOTION_STEPS = {
    "jog": "JOG",
    "tune inertia": "tune inertia",
    "tune score": "tune score",
    "tune friction": "tune friction",
    "tune notch": "tune notch",
    "tune gain-switching": "tune gain-switching",
}


def motion_setup(plan: Plan, profile: Profile) -> list[Requirement]:
    """The settings the plan's motion steps need (none when it has no motion step or the drive needs none)."""
    return requirements(profile) if any(s.name in MOTION_STEPS for s in plan.steps) else []


def unmet(plan: Plan, drive: Drive) -> list[tuple[Step, SetupRequired]]:
    """Each motion step on this drive that would be refused for its settings: one the drive does not hold and no
    earlier `set` step writes, or one a `set` step writes that takes effect only after a power cycle."""
    reqs = motion_setup(plan, drive.profile)
    if not reqs:
        return []
    readings = drive.read_entries([r.entry for r in reqs])
    values = {r.entry.code: reading.raw for r, reading in zip(reqs, readings, strict=True)}
    pending: set[str] = set()  # written by the plan, in effect after a power cycle the plan cannot make
    found: list[tuple[Step, SetupRequired]] = []
    for step in plan.steps:
        if step.units and drive.unit not in step.units:
            continue
        if step.name == "set":
            for entry, raw in SetStep().assignments(step, drive.profile):
                if entry.code in values and values[entry.code] != raw:
                    values[entry.code] = raw
                    if entry.effect == "power_cycle":
                        pending.add(entry.code)
        elif step.name in MOTION_STEPS:
            missing = [(r, values[r.entry.code]) for r in reqs if not r.met(values[r.entry.code])]
            waiting = [r for r in reqs if r.entry.code in pending and r.met(values[r.entry.code])]
            if missing or waiting:
                found.append((step, setup_required(drive.profile, MOTION_STEPS[step.name], missing, waiting)))
    return found
