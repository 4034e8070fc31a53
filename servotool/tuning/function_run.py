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
    OBSERVER_STEPS,
    Change,
    FunctionTrial,
    Progress,
    adaptive_notch_trial,
    friction_entries,
    friction_method,
    friction_trial,
    judged_trial,
    notch_entries,
    notch_trial,
    observer_trial,
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
    if function == "friction":
        how = friction_method(profile)
        if method == "host" and how == "observer":
            raise UsageError(f"tune friction: {profile.model} compensates friction by its own estimate: no host method")
        if method == "drive" and how == "feed-forward":
            raise UsageError(f"tune friction --method drive: {profile.model} has no friction estimate of its own")
        return "drive" if how == "observer" else "host"
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
    elif function == "friction" and chosen == "drive":
        return _observer_steps(drive, motion, repeats, before, keep=keep, save=save, clock=clock, progress=progress)
    elif function == "friction":
        trial = friction_trial(drive, motion, before, clock, progress)
    elif chosen == "drive":
        trial = adaptive_notch_trial(drive, motion, before, clock, progress)
    else:
        trial = notch_trial(drive, before)
    return judged_trial(drive, trial, motion, repeats, keep=keep, save=save, clock=clock, progress=progress)


VIBRATION_REFUSED = (
    "tune vibration: NOT RUN: {model}'s vibration suppression ({codes}) acts only in its position modes "
    "or inside its own auto-tune, neither of which servotool can command over Modbus, so no score could judge it: "
    "set it at the drive"
)


def vibration_refusal(profile: Profile) -> str:
    """Why `tune vibration` cannot run on this drive, in one line: SD25 maps its low-frequency vibration suppression
    (roles vibration_suppression_freq/_strength: Po240/Po242, PP/CSP only, L7937) and its automatic one lives inside
    the auto-tune started at the panel (Po174.C, L7480, L7656-7672); servotool's motions there are JOG (a speed
    mode), where neither acts. Reads nothing from the drive."""
    found = [e for r in ("vibration_suppression_freq", "vibration_suppression_strength") if (e := profile.role(r))]
    if not found:
        return f"tune vibration: {profile.model} maps no vibration suppression (roles vibration_suppression_*)"
    return VIBRATION_REFUSED.format(model=profile.model, codes=", ".join(e.code for e in found))


def _observer_steps(
    drive: Drive,
    motion: scoring.ScoreMotion,
    repeats: int,
    before: scoring.MeasuredScore,
    *,
    keep: bool,
    save: bool | None,
    clock: Clock | None,
    progress: Progress,
) -> FunctionTrial:
    """The drive's own friction compensation (SD25 section 9.6): its coefficient raised step by step (OBSERVER_STEPS),
    each step judged against the last one kept; the next step only after one kept. One trial comes back: the
    changes from the drive as found to what it holds now, judged against the first score."""
    first: FunctionTrial | None = None
    last: FunctionTrial | None = None
    for coefficient in OBSERVER_STEPS:
        scored = last.after if last is not None and last.after is not None else before
        trial = judged_trial(
            drive,
            observer_trial(drive, scored, coefficient),
            motion,
            repeats,
            keep=keep,
            save=save,
            clock=clock,
            progress=progress,
        )
        first = first or trial
        if not trial.kept or not [c for c in trial.changes if c.new != c.old]:
            if last is not None:
                last.reason += f"; {coefficient:g} % did not improve further ({trial.reason})"
            break
        last = trial
    if last is None or last is first:
        return last or first  # type: ignore[return-value]
    return _combined(first, last)  # type: ignore[arg-type]


def _combined(first: FunctionTrial, last: FunctionTrial) -> FunctionTrial:
    """Two kept steps as one trial: from the values as found to the last step's, judged first score to last."""
    found = {c.entry.code: c.old for c in first.changes}
    changes = [Change(c.entry, found.get(c.entry.code, c.old), c.new, c.why) for c in last.changes]
    assert first.before is not None and last.after is not None
    differences, verdict = scoring.compare(first.before.score, last.after.score, JUDGED["friction"])
    return FunctionTrial(
        "friction",
        changes=changes,
        before=first.before,
        after=last.after,
        differences=differences,
        verdict=verdict,
        kept=True,
        reason=last.reason,
        held=last.held,
        persisted=last.persisted,
    )


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
