"""The drive's own tuning functions run and judged (issue 34 item 2): score before, set the function up (journaled,
through the one write path), score after, keep the change only where the score improved beyond its spread (or when
asked to keep it), put everything back otherwise, and read the entries back to prove what the drive holds.

Two functions here: friction compensation (tune friction) from constant-speed torques, as the SDC manual's host
procedure takes them (L586-589: run below 10 r/min, read the torque monitor, write that value; the damping term from
the torque at speed less it), for every profile that maps compensation entries in % of rated torque; and a
torque-command notch (tune notch) at a resonance the line's sampling resolves, on a profile that maps notch entries.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from servotool.clock import Clock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.profile import Entry
from servotool.model.quantity import quantity
from servotool.ops import eeprom, journal
from servotool.ops.params import write_one
from servotool.tuning import score as scoring
from servotool.tuning import step
from servotool.tuning.fit.score import Difference
from servotool.tuning.fit.spectrum import Peak, spectrum
from servotool.tuning.preflight import FEATURE

SLOW_RPM = 5.0  # the SDC manual's friction run: below 10 r/min (L586)
SLOW_LEG_S = 1.5  # each slow leg's length; its last LATE_SHARE is averaged (the integral turns the torque round
LATE_SHARE = 0.4  # after the reversal first)
# The figures each function is for, and judged on (all are reported): friction compensation removes following
# error (a loop freed of friction overshoots as it would without it); a notch removes ringing.
JUDGED = {
    "friction": ("following_error_rms", "following_error_peak", "iae"),
    "notch": ("overshoot", "settling", "ripple", "iae", "following_error_rms"),
    # a stiffer gain while moving is for tracking, and must not cost overshoot or settling
    "gain-switching": ("following_error_rms", "following_error_peak", "iae", "overshoot", "settling"),
}
MIN_COMP_PCT = 0.5  # a friction term below this share of rated torque (or two torque-reading steps) is left at 0:
#                    nothing to compensate that the score could show
NOTCH_WIDTH_LEVEL = 2  # the notch set at a resonance: IS620P's default width level
NOTCH_DEPTH_LEVEL = 0  # cut out at its centre
NOTCHES = 4


@dataclass(frozen=True)
class Change:
    entry: Entry
    old: int
    new: int
    why: str

    @property
    def old_value(self) -> float:
        return float(raw_to_eng(self.entry, self.old))

    @property
    def new_value(self) -> float:
        return float(raw_to_eng(self.entry, self.new))


@dataclass
class FunctionTrial:
    """What a function did: the changes tried, the scores around them, the verdict and what the drive holds now."""

    function: str
    changes: list[Change] = field(default_factory=list)
    before: scoring.MeasuredScore | None = None
    after: scoring.MeasuredScore | None = None
    differences: list[Difference] = field(default_factory=list)
    verdict: str = "unchanged"  # better | worse | unchanged (the scores'); nothing tried: unchanged
    kept: bool = False
    reason: str = ""
    found: dict[str, float] = field(default_factory=dict)  # what the function measured (friction, peaks)
    peaks: list[Peak] = field(default_factory=list)
    nyquist_hz: float = 0.0
    held: dict[str, float] = field(default_factory=dict)  # the entries as read back at the end
    persisted: bool | None = None


Progress = Callable[[str], None]


def _quiet(_text: str) -> None:
    pass


def judged_trial(
    drive: Drive,
    trial: FunctionTrial,
    motion: scoring.ScoreMotion,
    repeats: int,
    *,
    keep: bool = False,
    save: bool | None = None,
    clock: Clock | None = None,
    progress: Progress = _quiet,
) -> FunctionTrial:
    """Write trial.changes (journaled), score after, keep them where the score improved beyond its spread (or keep),
    else put the old values back; then read every entry back. trial.before must be scored already."""
    assert trial.before is not None
    changes = [c for c in trial.changes if c.new != c.old]
    if not changes:
        trial.reason = trial.reason or "nothing to change: the drive holds these values already"
        _read_back(drive, trial)
        return trial
    targets = {c.entry.code: c.new for c in changes}
    before = {c.entry.code: c.old for c in changes}
    with journal.operation(drive, f"tune {trial.function}", None, targets, before):
        with eeprom.persistence(drive, save) as kept_state:
            for c in changes:
                write_one(drive, c.entry, c.new, c.old)
        progress("set: " + ", ".join(f"{c.entry.code} {c.old_value:g} -> {c.new_value:g}" for c in changes))
        try:
            trial.after = scoring.measure(drive, motion, repeats, clock)
        except BaseException:
            _put_back(drive, changes, save)
            raise
        trial.differences, trial.verdict = scoring.compare(
            trial.before.score, trial.after.score, JUDGED.get(trial.function)
        )
        trial.kept = trial.verdict == "better" or keep
        if trial.kept:
            trial.persisted = kept_state["persisted"]
            trial.reason = (
                "the score improved beyond its spread"
                if trial.verdict == "better"
                else f"kept as asked (--keep), the score {_verdict_words(trial.verdict)}"
            )
        else:
            _put_back(drive, changes, save)
            trial.reason = f"the score {_verdict_words(trial.verdict)}: the previous values were written back"
    _read_back(drive, trial)
    return trial


def _verdict_words(verdict: str) -> str:
    return {"worse": "got worse", "unchanged": "did not improve beyond its spread"}.get(verdict, "improved")


def _put_back(drive: Drive, changes: list[Change], save: bool | None) -> None:
    with eeprom.persistence(drive, save):
        for c in changes:
            write_one(drive, c.entry, c.old)


def _read_back(drive: Drive, trial: FunctionTrial) -> None:
    """The entries the trial touched, as the drive holds them now (the proof of what was kept or put back)."""
    entries = [c.entry for c in trial.changes]
    if entries:
        trial.held = {r.entry.code: float(raw_to_eng(r.entry, r.raw)) for r in drive.read_entries(entries)}


# ----- friction compensation -------------------------------------------------------------------------------------

FRICTION_ROLES = ("friction_comp_fwd", "friction_comp_rev", "viscous_comp_fwd", "viscous_comp_rev")


def friction_entries(drive: Drive) -> dict[str, Entry]:
    """The compensation entries in % of rated torque the profile maps (a usage error where it maps none)."""
    found = {r: e for r in FRICTION_ROLES if (e := drive.profile.role(r)) is not None and e.unit == "%"}
    if "friction_comp_fwd" not in found:
        raise UsageError(
            f"tune friction: {drive.profile.model} maps no friction compensation in % of rated torque "
            "(roles friction_comp_fwd/_rev)"
        )
    return found


def constant_speed_torque(
    drive: Drive, speed_rpm: float, duration_s: float, clock: Clock | None
) -> tuple[float, float, float]:
    """(forward, reverse) mean torque (% of rated) over the last LATE_SHARE of a leg each way at speed_rpm, and the
    torque reading's standard deviation there (the motion is the step check's: bounded, put back)."""
    legs, _ = step.step_legs(drive, speed_rpm, duration_s, clock, torque=True)
    means, spread = [], []
    for leg in legs:
        t, q = np.asarray(leg.t), np.asarray(leg.torque_pct)
        late = q[t >= (1.0 - LATE_SHARE) * duration_s]
        means.append(float(np.mean(late)) if late.size else math.nan)
        spread.append(float(np.std(late)) if late.size > 1 else 0.0)
    return means[0], means[1], max(spread)


def friction_trial(
    drive: Drive,
    motion: scoring.ScoreMotion,
    before: scoring.MeasuredScore,
    clock: Clock | None = None,
    progress: Progress = _quiet,
) -> FunctionTrial:
    """The compensation the constant-speed torques call for: Coulomb by direction from a leg each way below
    10 r/min; the damping term (where mapped) from the torque at the test speed less it, scaled to the rated
    speed (SDC L589: 'if rated speed cannot be reached, scale proportionally')."""
    entries = friction_entries(drive)
    motor = drive.profile.motor
    rated = motor.rated_speed_rpm if motor is not None else 3000.0
    slow_fwd, slow_rev, noise = constant_speed_torque(drive, SLOW_RPM, SLOW_LEG_S, clock)
    progress(f"at {SLOW_RPM:g} rpm: torque {slow_fwd:+.1f} % forward, {slow_rev:+.1f} % reverse")
    trial = FunctionTrial("friction", before=before)
    trial.found = {"coulomb_fwd": slow_fwd, "coulomb_rev": -slow_rev, "torque_noise": noise}
    floor = max(MIN_COMP_PCT, 2 * drive.profile.need_role("torque_feedback", FEATURE).scale)

    def term(x: float) -> float:
        return x if x >= floor else 0.0

    wanted = {"friction_comp_fwd": term(slow_fwd), "friction_comp_rev": term(-slow_rev)}
    if "viscous_comp_fwd" in entries or "viscous_comp_rev" in entries:
        fast_fwd, fast_rev, _ = constant_speed_torque(drive, motion.speed_rpm, motion.duration_s, clock)
        scale = rated / (motion.speed_rpm - SLOW_RPM)
        wanted["viscous_comp_fwd"] = term((fast_fwd - slow_fwd) * scale)
        wanted["viscous_comp_rev"] = term((slow_rev - fast_rev) * scale)
        trial.found["viscous_fwd_at_rated"] = wanted["viscous_comp_fwd"]
        trial.found["viscous_rev_at_rated"] = wanted["viscous_comp_rev"]
    what = {
        "friction_comp_fwd": "Coulomb friction, forward",
        "friction_comp_rev": "Coulomb friction, reverse",
        "viscous_comp_fwd": "damping at rated speed, forward",
        "viscous_comp_rev": "damping at rated speed, reverse",
    }
    current = {r.entry.code: r.raw for r in drive.read_entries([entries[r] for r in wanted if r in entries])}
    for role, value in wanted.items():
        entry = entries.get(role)
        if entry is None:
            continue
        trial.changes.append(Change(entry, current[entry.code], eng_to_raw(entry, value), what[role]))
    return trial


# ----- notch ------------------------------------------------------------------------------------------------------


def notch_entries(drive: Drive) -> list[tuple[Entry, Entry, Entry]]:
    """(frequency, width level, depth or attenuation) of each notch the profile maps (a usage error where none)."""
    p = drive.profile
    found = []
    for n in range(1, NOTCHES + 1):
        parts = [p.role(f"notch{n}_{what}") for what in ("freq", "width")]
        parts.append(p.role(f"notch{n}_depth") or p.role(f"notch{n}_attenuation"))
        if all(e is not None for e in parts):
            found.append((parts[0], parts[1], parts[2]))  # type: ignore[arg-type]
    if not found:
        raise UsageError(f"tune notch: {p.model} maps no torque-command notch (roles notchN_freq/_width/_depth)")
    return found


def _attenuates(drive: Drive, entry: Entry) -> bool:
    """Whether a notch's third entry is an attenuation (role notchN_attenuation) rather than a depth passed."""
    return any(drive.profile.role(f"notch{n}_attenuation") is entry for n in range(1, NOTCHES + 1))


def resonance_peaks(measured: scoring.MeasuredScore) -> tuple[list[Peak], float]:
    """The peaks of the speed (and torque) after the step's ramp in the score's first run, and the Nyquist limit:
    what the line's sampling lets the finder see."""
    if not measured.legs:
        return [], 0.0
    leg = measured.legs[0]
    t = np.asarray(leg.t)
    keep = t > leg.command_ms / 1000.0 + leg.ramp_ms / 1000.0 * measured.motion.speed_rpm / 3000.0 + 0.01
    peaks: list[Peak] = []
    nyquist = 0.0
    for signal in (leg.speed_rpm, leg.torque_pct):
        if len(signal) != t.size or np.sum(keep) < 8:
            continue
        found = spectrum(t[keep], np.asarray(signal)[keep])
        if found is None:
            continue
        nyquist = found.nyquist_hz
        for peak in found.peaks:
            if all(abs(peak.hz - p.hz) > 2 * found.resolution_hz for p in peaks):
                peaks.append(peak)
    return peaks, nyquist


def notch_target(drive: Drive, peaks: list[Peak], nyquist_hz: float) -> tuple[Peak | None, str]:
    """The peak a notch would take (the strongest resolvable one inside the drive's notch range) and why; None
    with the reason where there is none (or the drive maps no notch)."""
    p = drive.profile
    freq_e = p.role("notch1_freq")
    if freq_e is None:
        return None, f"{p.model} maps no torque-command notch: no notch proposed"
    lo, hi = float(raw_to_eng(freq_e, freq_e.min)), float(raw_to_eng(freq_e, freq_e.max))
    usable = [x for x in peaks if x.resolvable and lo <= x.hz <= hi]
    if not usable:
        seen = ", ".join(f"{x.hz:.0f} Hz" for x in peaks) or "no peak"
        return None, (
            f"nothing to notch: {seen} seen; sampled at {2 * nyquist_hz:.0f}/s, nothing above {nyquist_hz:.0f} Hz "
            f"is visible, and the drive's notch spans {lo:g}..{hi:g} Hz"
        )
    target = max(usable, key=lambda x: x.amplitude)
    return target, f"notch proposed at {target.hz:.0f} Hz ({freq_e.code} range {lo:g}..{hi:g} Hz)"


def notch_proposal(drive: Drive, peaks: list[Peak], nyquist_hz: float) -> dict[str, object]:
    """The notch the resonance finder proposes, for the report: frequency (or None) and why."""
    target, reason = notch_target(drive, peaks, nyquist_hz)
    return {"frequency": quantity(round(target.hz, 1), "Hz") if target else None, "reason": reason}


def adaptive_notch_trial(
    drive: Drive,
    motion: scoring.ScoreMotion,
    before: scoring.MeasuredScore,
    clock: Clock | None = None,
    progress: Progress = _quiet,
) -> FunctionTrial:
    """The drive's own adaptive notch (role adaptive_notch: IS620P H09-02): one notch adapting (mode 1) while the
    test motion excites the machine, then frozen (mode 0: not updated) and the notch read back: what the drive
    chose becomes the trial's change (judged_trial keeps or puts back). The mode goes back to what it was, also on
    failure; the notch as found is the journal's 'before'."""
    mode_e = drive.profile.role("adaptive_notch")
    if mode_e is None:
        raise UsageError(f"tune notch --method drive: {drive.profile.model} maps no adaptive notch")
    groups = notch_entries(drive)
    flat = [e for g in groups for e in g]
    found = {r.entry.code: r.raw for r in drive.read_entries([mode_e, *flat])}
    mode = found[mode_e.code]
    trial = FunctionTrial("notch", before=before)
    with journal.operation(drive, "tune notch", None, {mode_e.code: 1}, dict(found)):
        try:
            with eeprom.persistence(drive, False):
                write_one(drive, mode_e, 1, mode)
            progress(f"{mode_e.code} = 1: the drive adapts one notch while the axis moves")
            scoring.measure(drive, motion, 1, clock)
        finally:
            with eeprom.persistence(drive, False):
                write_one(drive, mode_e, mode)
    chosen = {r.entry.code: r.raw for r in drive.read_entries(flat)}
    for entry in flat:
        if chosen[entry.code] != found[entry.code]:
            # what the drive set: written back as found first, then set again by judged_trial (journaled)
            why = "set by the drive's adaptive notch"
            trial.changes.append(Change(entry, found[entry.code], chosen[entry.code], why))
    if trial.changes:
        with eeprom.persistence(drive, False):
            for c in trial.changes:
                write_one(drive, c.entry, c.old)
        freq = next((c for c in trial.changes if c.entry in [g[0] for g in groups]), None)
        if freq is not None:
            trial.found = {"resonance": freq.new_value}
        progress("the drive chose " + ", ".join(f"{c.entry.code} = {c.new_value:g}" for c in trial.changes))
    else:
        trial.reason = f"the drive's adaptive notch set nothing ({mode_e.code} = 1 during the test motion)"
    return trial


def notch_trial(drive: Drive, before: scoring.MeasuredScore) -> FunctionTrial:
    """A notch at notch_target's peak, on the first notch that is off (depth at its maximum or width 0: it passes
    everything) or else the first; no change where there is no target."""
    trial = FunctionTrial("notch", before=before)
    trial.peaks, trial.nyquist_hz = resonance_peaks(before)
    groups = notch_entries(drive)
    target, trial.reason = notch_target(drive, trial.peaks, trial.nyquist_hz)
    if target is None:
        return trial
    trial.found = {"resonance": target.hz}
    flat = [e for g in groups for e in g]
    raws = {r.entry.code: r.raw for r in drive.read_entries(flat)}

    def passes(g: tuple[Entry, Entry, Entry]) -> bool:  # off: passes everything
        cut = raws[g[2].code] == 0 if _attenuates(drive, g[2]) else raws[g[2].code] >= g[2].max
        return cut or raws[g[1].code] == 0

    free = next((g for g in groups if passes(g)), groups[0])
    full = (
        (float(raw_to_eng(free[2], free[2].max)), "attenuation (cut out at its centre)")
        if _attenuates(drive, free[2])
        else (
            NOTCH_DEPTH_LEVEL,
            "depth level (0: cut out at its centre)",
        )
    )
    for entry, value, why in (
        (free[0], target.hz, f"notch at the {target.hz:.0f} Hz peak"),
        (free[1], NOTCH_WIDTH_LEVEL, "width level"),
        (free[2], full[0], full[1]),
    ):
        trial.changes.append(Change(entry, raws[entry.code], eng_to_raw(entry, value), why))
    return trial


__all__ = [
    "FEATURE",
    "FunctionTrial",
    "friction_trial",
    "judged_trial",
    "notch_trial",
]
