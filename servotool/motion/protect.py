"""The drive's own protections, set for the duration of a motion: harm bounded where time cannot be.

Where the profile maps them (roles, see profiles/SCHEMA.md), before a JOG, an identification or a step check moves:
the speed limit (role max_speed) a little above the motion's peak; a software overtravel fence around where the
motion starts (SD25 Po136-Po145, So-39 = stop: the drive stops the motor there even with this program dead); the
locked-rotor trip (SD25 So-34/So-40, AL-30) and speed-regulator saturation detection (SDC PN120/PN79, AL-6) on with a
short time; the overload multiple (SDC PN65) at most OVERLOAD_PCT. A protection only tightens what the drive has. The
originals go into the motion's settings to put back and the journal before anything is written, so the motion's
end (or, after a kill -9, the next command) puts them back like its speed and ramp (motion.jogger).

`plan` decides from the drive's present values (reads only); `apply` writes. The plan's facts (what bounds the
motion) go with the dead-man bound the CLI prints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from servotool.drive import Drive
from servotool.model.codec import eng_to_raw, raw_to_eng
from servotool.model.lookup import enum_value
from servotool.model.profile import Entry, Profile
from servotool.motion import deadman
from servotool.motion.deadman import DeadManBound
from servotool.motion.forced_inputs import wired_inputs_warning
from servotool.ops import journal
from servotool.ops.params import write_one

SPEED_LIMIT_MARGIN = 1.1  # the speed limit this far above the motion's peak: the command itself is never clipped
LOCKED_ROTOR_S = 0.5  # a locked rotor trips after at most this long during a motion
SATURATION_S = 0.5  # a saturated speed regulator (a jammed machine) trips after at most this long
OVERLOAD_PCT = 200.0  # the overload multiple during a motion, at most (% of rated)
FENCE_ROLES = (
    "fence_action",
    "fence_reverse_counts",
    "fence_reverse_turns",
    "fence_forward_counts",
    "fence_forward_turns",
    "fence_origin_counts",
    "fence_origin_turns",
)  # in the order they are put back: the action first, the origin last (a fence stays around the axis throughout)


@dataclass(frozen=True)
class Protections:
    """What one motion sets on the drive (code -> raw, in the order they are written) and the facts it gives."""

    writes: tuple[tuple[str, int], ...]
    restore_order: tuple[str, ...]  # codes in the order their originals are put back
    speed_limit_rpm: float | None = None
    speed_limit_code: str = ""
    fence_rev: float | None = None
    fence_code: str = ""
    trips: tuple[str, ...] = ()  # e.g. "a locked rotor trips AL-30 after 0.5 s (So-34, So-40)"
    skipped: tuple[str, ...] = ()  # what the profile maps but cannot be used here, and why

    def notes(self) -> tuple[str, ...]:
        """The facts in words, one each."""
        out = []
        if self.speed_limit_rpm is not None:
            out.append(f"the drive's speed limit {self.speed_limit_code} at {self.speed_limit_rpm:g} rpm")
        if self.fence_rev is not None:
            out.append(f"the drive's overtravel fence ({self.fence_code}) at ±{self.fence_rev:.2f} rev from the start")
        return (*out, *self.trips, *self.skipped)


def _named(entry: Entry, name: str) -> int | None:
    return enum_value(entry.enum, name)


def _eng(entry: Entry, raw: int) -> float:
    return float(raw_to_eng(entry, raw))


def plan(drive: Drive, peak_rpm: float, fence_rev: float | None) -> Protections:
    """The protections for a motion up to peak_rpm (rpm) whose travel stays within fence_rev either way of where it
    starts (None: unknown, no fence), from the drive's present values."""
    p = drive.profile
    roles = (
        "max_speed",
        *FENCE_ROLES,
        "encoder_counts",
        "encoder_turns",
        "locked_rotor_check",
        "locked_rotor_time",
        "saturation_check",
        "saturation_time",
        "overload_multiple",
    )
    entries = {r: e for r in roles if (e := p.role(r)) is not None and e.readable}
    now = {r: reading.raw for r, reading in zip(entries, drive.read_entries(list(entries.values())), strict=True)}
    writes: dict[str, int] = {}
    restore: list[str] = []
    speed: tuple[float, str] | None = None
    fence_at: tuple[float, str] | None = None
    trips: list[str] = []
    skipped: list[str] = []

    def tighten(role: str, raw: int) -> None:
        e = entries[role]
        if e.cls != "Pn" or e.effect == "power_cycle":
            skipped.append(f"{e.code} takes effect only after a power cycle: not set for the motion")
            return
        if raw != now[role]:
            writes[e.code] = raw
            restore.append(e.code)

    if "max_speed" in entries:
        e = entries["max_speed"]
        limit = math.ceil(abs(peak_rpm) * SPEED_LIMIT_MARGIN / e.scale) * e.scale
        raw = min(now["max_speed"], eng_to_raw(e, limit))
        tighten("max_speed", raw)
        speed = (_eng(e, raw), e.code)
    fenced = all(r in entries for r in (*FENCE_ROLES, "encoder_counts", "encoder_turns"))
    if fenced and fence_rev is None:
        skipped.append("no overtravel fence: the motion's extent is not known (an interactive JOG: give --travel)")
    elif fenced and fence_rev is not None:
        fence = _fence(p, entries, now, fence_rev)
        if isinstance(fence, str):
            skipped.append(fence)
        else:
            for role in reversed(FENCE_ROLES):  # the origin first, the action last
                tighten(role, fence[role])
            fence_at = (fence_rev, entries["fence_action"].code)
    if "locked_rotor_check" in entries and "locked_rotor_time" in entries:
        check, time = entries["locked_rotor_check"], entries["locked_rotor_time"]
        on = _named(check, "on")
        if on is not None:
            tighten("locked_rotor_check", on)
            t_raw = min(now["locked_rotor_time"], eng_to_raw(time, LOCKED_ROTOR_S * 1000.0))
            tighten("locked_rotor_time", t_raw)
            trips.append(
                f"a locked rotor trips {_alarm(p, 'locked_rotor')} after {_eng(time, t_raw) / 1000.0:g} s "
                f"({check.code}, {time.code})"
            )
    if "saturation_check" in entries and "saturation_time" in entries:
        check, time = entries["saturation_check"], entries["saturation_time"]
        detect = _named(check, "detect")
        if detect is not None:
            tighten("saturation_check", detect)
            present = now["saturation_time"]
            t_raw = eng_to_raw(time, SATURATION_S * 1000.0)
            t_raw = min(present, t_raw) if present > 0 else t_raw
            tighten("saturation_time", t_raw)
            trips.append(
                f"a jammed machine (speed regulator saturated) trips {_alarm(p, 'saturation')} after "
                f"{_eng(time, t_raw) / 1000.0:g} s ({check.code}, {time.code})"
            )
    if "overload_multiple" in entries:
        e = entries["overload_multiple"]
        raw = min(now["overload_multiple"], eng_to_raw(e, OVERLOAD_PCT))
        tighten("overload_multiple", raw)
        trips.append(f"torque at most {_eng(e, raw):g} % of rated ({e.code})")
    return Protections(
        writes=tuple(writes.items()),
        restore_order=tuple(_restore_order(p, restore)),
        speed_limit_rpm=speed[0] if speed is not None else None,
        speed_limit_code=speed[1] if speed is not None else "",
        fence_rev=fence_at[0] if fence_at is not None else None,
        fence_code=fence_at[1] if fence_at is not None else "",
        trips=tuple(trips),
        skipped=tuple(skipped),
    )


def _restore_order(profile: Profile, codes: list[str]) -> list[str]:
    """The fence's entries in FENCE_ROLES order (its action first), then the rest as written."""
    fence = [e.code for r in FENCE_ROLES if (e := profile.role(r)) is not None and e.code in codes]
    return fence + [c for c in codes if c not in fence]


def _fence(profile: Profile, entries: dict[str, Entry], now: dict[str, int], fence_rev: float) -> dict[str, int] | str:
    """The fence roles' raw values that centre a fence of fence_rev either way on the encoder's present position,
    or why it cannot be set here."""
    stop = _named(entries["fence_action"], "stop")
    turns_e, motor = entries["encoder_turns"], profile.motor
    if stop is None or motor is None:
        return f"{entries['fence_action'].code} has no 'stop' setting or the profile no motor data: no fence"
    turns, counts = now["encoder_turns"], now["encoder_counts"]
    whole = math.floor(fence_rev)
    part = round((fence_rev - whole) * motor.counts_per_rev)
    wrap = turns_e.max + 1 if turns_e.min == 0 else None
    if wrap is not None and (turns - whole - 1 < 0 or turns + whole + 1 >= wrap):
        return (
            f"no overtravel fence: it would span the encoder's multi-turn wrap at {turns_e.max}/0 "
            f"({turns_e.code} = {turns}), where the manual does not say how the range is compared"
        )
    values = {
        "fence_action": stop,
        "fence_origin_turns": turns,
        "fence_origin_counts": counts,
        "fence_forward_turns": whole,
        "fence_forward_counts": part,
        "fence_reverse_turns": whole,
        "fence_reverse_counts": part,
    }
    for role, raw in values.items():
        e = entries[role]
        if not e.min <= raw <= e.max:
            return f"no overtravel fence: {e.code} cannot hold {raw} (range {e.min}..{e.max})"
    return values


def _alarm(profile: Profile, kind: str) -> str:
    alarm = profile.alarm_of_kind(kind)
    return alarm.display if alarm is not None else "an alarm"


def apply(drive: Drive, planned: Protections, saved: dict[str, int]) -> None:
    """Write the planned protections: every original first recorded in `saved` (code -> raw, the motion's settings
    put back as it ends; an original already there, a dead process's, wins) and journaled, then the writes."""
    if not planned.writes:
        return
    p = drive.profile
    entries = [p.entry(code) for code in planned.restore_order]
    originals = {e.code: r.raw for e, r in zip(entries, drive.read_entries(entries), strict=True)}
    for code in planned.restore_order:
        saved.setdefault(code, originals[code])
    journal.note_settings(drive, saved)
    for code, raw in planned.writes:
        entry = p.entry(code)
        if originals.get(code) != raw:
            write_one(drive, entry, raw, originals.get(code))


def limited(bound: DeadManBound, planned: Protections | None, profile: Profile) -> DeadManBound:
    """The dead-man bound with what else bounds the motion: the planned protections and, on a forced-input drive,
    the wired-input warning."""
    warning = wired_inputs_warning(profile)
    return deadman.with_limits(
        bound,
        planned.fence_rev if planned is not None else None,
        planned.speed_limit_rpm if planned is not None else None,
        (*((warning,) if warning else ()), *(planned.notes() if planned is not None else ())),
    )


def planned_bound(drive: Drive, bound: DeadManBound, peak_rpm: float, fence_rev: float | None) -> DeadManBound:
    """A motion's dead-man bound (deadman.motion_bound) with the protections it will set (see plan)."""
    return limited(bound, plan(drive, peak_rpm, fence_rev), drive.profile)
