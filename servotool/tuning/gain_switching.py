"""Gain switching set up as a judged function (tune gain-switching): a stiffer second gain set while the motor turns,
the first at rest, on the speed condition the manual documents (SD25 Po130 = 2, section 9.3.5, L7851-7869:
'above Po131 gain 2 at once, below it gain 1 after the Po135 delay'; one of its stated uses is 'a higher gain while
running for better command tracking'). judged_trial keeps it only where the score improves beyond its spread.

A profile whose switching mode names no conditions (IS620P H08-09: its volume prints the range only) is refused with
the reason: nothing is invented and nothing written.
"""

from __future__ import annotations

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.profile import Entry, Profile
from servotool.tuning import score as scoring
from servotool.tuning.drive_functions import Change, FunctionTrial

SPEED_CONDITION = "speed"
# gain 2's speed-loop gain against gain 1's, its integral time longer by as much: the same integral action, a stiffer
# proportional one (the integral time kept overshot more on the score's ramped step, 4.4 -> 5.1 %; shortened with the
# gain, 4.6 -> 9.3 %; lengthened, 4.4 -> 0.8 %: SD25 at 10 Hz, load ratio 3, virtual time)
DEFAULT_FACTOR = 1.5
LEVEL_SHARE = 0.1  # the switching speed: this share of the test speed
DELAY_MS = 50.0  # gain 2 -> gain 1 after this long below the switching speed (SD25 factory: 100 ms)
ROLES = (
    "gain_switch_mode",
    "speed_loop_gain_2",
    "speed_loop_integral_2",
    "position_loop_gain_2",
    "gain_switch_speed",
    "gain_switch_delay",
)


def switching_entries(profile: Profile) -> dict[str, Entry]:
    """The entries gain switching on the speed condition needs; a usage error naming why where a profile lacks
    them or its manual does not describe the condition."""
    mode = profile.role("gain_switch_mode")
    if mode is None:
        raise UsageError(f"tune gain-switching: {profile.model} maps no gain switching (role gain_switch_mode)")
    if SPEED_CONDITION not in mode.enum.values():
        why = mode.unverified or f"{mode.code} names no conditions"
        raise UsageError(
            f"tune gain-switching: UNVERIFIED on {profile.model}: {mode.code} ({mode.name}): {why}; nothing written"
        )
    found = {r: e for r in ROLES if (e := profile.role(r)) is not None}
    missing = [r for r in ROLES if r not in found]
    if missing:
        raise UsageError(f"tune gain-switching: {profile.model} maps no {', '.join(missing)}")
    return found


def check_factor(factor: float) -> float:
    if not 1.0 < factor <= 4.0:
        raise UsageError("--factor must be above 1 and at most 4 (gain 2 against gain 1)")
    return factor


def gain_switching_trial(
    drive: Drive, motion: scoring.ScoreMotion, before: scoring.MeasuredScore, factor: float = DEFAULT_FACTOR
) -> FunctionTrial:
    """Gain 2 = gain 1's speed gain and integral time x factor (its integral action as gain 1's), the same position
    gain; switched in above
    LEVEL_SHARE of the test speed, out DELAY_MS after it falls below (each clamped to its entry's range)."""
    check_factor(factor)
    p = drive.profile
    entries = switching_entries(p)
    first = [p.need_role(r, "tune gain-switching") for r in ("speed_loop_gain", "speed_loop_integral")]
    first.append(p.need_role("position_loop_gain", "tune gain-switching"))
    now = {r.entry.code: r.raw for r in drive.read_entries([*first, *entries.values()])}

    def eng(e: Entry) -> float:
        return float(raw_to_eng(e, now[e.code]))

    def raw(e: Entry, value: float) -> int:
        return max(e.min, min(e.max, eng_to_raw(e, value)))

    mode = entries["gain_switch_mode"]
    condition = next(k for k, v in mode.enum.items() if v == SPEED_CONDITION)
    wanted = (
        (entries["speed_loop_gain_2"], raw(entries["speed_loop_gain_2"], eng(first[0]) * factor), "gain 2 speed gain"),
        (
            entries["speed_loop_integral_2"],
            raw(entries["speed_loop_integral_2"], eng(first[1]) * factor),
            "gain 2 integral time",
        ),
        (entries["position_loop_gain_2"], raw(entries["position_loop_gain_2"], eng(first[2])), "gain 2 position gain"),
        (
            entries["gain_switch_speed"],
            raw(entries["gain_switch_speed"], LEVEL_SHARE * motion.speed_rpm),
            "switch to gain 2 above",
        ),
        (entries["gain_switch_delay"], raw(entries["gain_switch_delay"], DELAY_MS), "back to gain 1 after"),
        (mode, condition, f"switch on speed ({mode.enum[condition]})"),
    )
    trial = FunctionTrial("gain-switching", before=before)
    trial.found = {
        "gain1_speed_gain": eng(first[0]),
        "gain1_integral_time": eng(first[1]),
        "factor": factor,
    }
    for entry, new, why in wanted:
        trial.changes.append(Change(entry, now[entry.code], new, why))
    return trial
