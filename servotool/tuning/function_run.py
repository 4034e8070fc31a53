"""The one use case of the drive's own functions (the commands `tune friction|notch|gain-switching` and a plan's
steps of those names): check what the function needs, score before, set it up, judge, keep or put back, read back;
and the trial's facts as JSON, every figure with its unit."""

from __future__ import annotations

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.profile import Profile
from servotool.model.quantity import quantity
from servotool.ops import eeprom
from servotool.tuning import gain_switching
from servotool.tuning import score as scoring
from servotool.tuning.drive_functions import (
    JUDGED,
    FunctionTrial,
    Progress,
    adaptive_notch_trial,
    friction_entries,
    friction_trial,
    judged_trial,
    notch_entries,
    notch_trial,
)
from servotool.tuning.fit.spectrum import Peak


def _quiet(_text: str) -> None:
    pass


FUNCTIONS = ("friction", "notch", "gain-switching")
METHODS = ("drive", "host")


def check_function(profile: Profile, function: str, method: str | None) -> str:
    """The function's method on this profile (notch: the drive's adaptive one where mapped, else host; friction:
    host); a usage error for an unknown function or a method the profile lacks. Reads nothing from the drive."""
    if function not in FUNCTIONS:
        raise UsageError(f"unknown function {function!r} (functions: {', '.join(FUNCTIONS)})")
    if method is not None and method not in METHODS:
        raise UsageError(f"method must be drive or host, got {method!r}")
    if function != "notch":
        if method == "drive":
            raise UsageError(f"tune {function} has no drive method")
        return "host"
    adaptive = profile.role("adaptive_notch") is not None
    if method == "drive" and not adaptive:
        raise UsageError(f"tune notch --method drive: {profile.model} maps no adaptive notch")
    return method or ("drive" if adaptive else "host")


def check_entries(drive: Drive, function: str) -> None:
    """A usage error where the profile lacks what the function writes (before anything moves)."""
    if function == "friction":
        friction_entries(drive)
    elif function == "notch":
        notch_entries(drive)
    else:
        gain_switching.switching_entries(drive.profile)


def run_function(
    drive: Drive,
    function: str,
    motion: scoring.ScoreMotion,
    repeats: int,
    *,
    method: str | None = None,
    keep: bool = False,
    save: bool | None = None,
    factor: float | None = None,
    clock: Clock | None = None,
    progress: Progress = _quiet,
) -> FunctionTrial:
    """Score before, set the function up, score after, keep or put back, read back (judged_trial): what `tune
    friction` and `tune notch` do, and a plan's steps of the same names. motion is the planned one
    (scoring.planned); the entries the function needs are checked before anything moves; factor: gain switching's
    second gain against the first (gain_switching.DEFAULT_FACTOR)."""
    chosen = check_function(drive.profile, function, method)
    check_entries(drive, function)
    eeprom.check_save_request(drive.profile, save)
    before = scoring.measure(drive, motion, repeats, clock)
    if function == "gain-switching":
        trial = gain_switching.gain_switching_trial(drive, motion, before, factor or gain_switching.DEFAULT_FACTOR)
    elif function == "friction":
        trial = friction_trial(drive, motion, before, clock, progress)
    elif chosen == "drive":
        trial = adaptive_notch_trial(drive, motion, before, clock, progress)
    else:
        trial = notch_trial(drive, before)
    return judged_trial(drive, trial, motion, repeats, keep=keep, save=save, clock=clock, progress=progress)


def peak_json(p: Peak) -> dict[str, object]:
    return {"frequency": quantity(round(p.hz, 1), "Hz"), "amplitude": round(p.amplitude, 3), "resolved": p.resolvable}


def trial_json(trial: FunctionTrial, profile_id: str) -> dict[str, object]:
    """A trial's facts, every figure with its unit: the changes, the scores before and after, the verdict, what the
    drive holds (read back)."""
    return {
        "function": trial.function,
        "changes": [
            {
                "code": c.entry.code,
                "old": quantity(c.old_value, c.entry.unit),
                "new": quantity(c.new_value, c.entry.unit),
                "what": c.why,
            }
            for c in trial.changes
        ],
        "found": {k: round(v, 3) for k, v in trial.found.items()},
        "peaks": [peak_json(p) for p in trial.peaks],
        "verdict": trial.verdict,
        "judged_on": list(JUDGED.get(trial.function, ())),
        "kept": trial.kept,
        "reason": trial.reason,
        "held": {c.entry.code: quantity(trial.held.get(c.entry.code), c.entry.unit) for c in trial.changes},
        "persisted": trial.persisted,
        "before": scoring.score_json(trial.before, profile_id) if trial.before else None,
        "after": scoring.score_json(trial.after, profile_id) if trial.after else None,
        "comparison": scoring.comparison_json(trial.differences, trial.verdict) if trial.after else None,
    }
