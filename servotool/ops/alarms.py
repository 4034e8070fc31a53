"""Alarms: read the current alarm and the drive's own history of them, clear it, through the profile's roles.

Each alarm comes with the manual's causes and remedies where the manual prints them (the profile's alarm_causes;
where it prints none, that is said, never a cause made up), and each past one with what the drive recorded beside
it (alarm_log: the speed, bus voltage, current, run time at the fault, where the drive keeps them).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from servotool.drive import Drive, Reading
from servotool.errors import VerifyError
from servotool.model.alarm_notes import CauseRemedy, RecordSelector
from servotool.model.codec import as_held
from servotool.model.profile import Entry, Profile

FEATURE = "alarm"
# What a drive records beside an alarm, in words, in the order shown.
CONTEXT_WORDS = {
    "time": "run time",
    "speed": "speed",
    "bus_voltage": "bus voltage",
    "current": "current",
    "current_u": "U-phase current",
    "current_v": "V-phase current",
    "inputs": "inputs on",
    "outputs": "outputs on",
}


@dataclass(frozen=True)
class ManualNote:
    """What the manual says an alarm's causes and remedies are: the pairs and their lines, or why there are none."""

    causes: tuple[CauseRemedy, ...]
    source: str  # the manual lines of these causes, or of the table that has none for this alarm
    note: str = ""  # set where the manual gives none: what it says instead

    def as_json(self) -> dict[str, object]:
        return {
            "causes": [{"cause": c.cause, "remedy": c.remedy} for c in self.causes],
            "source": self.source,
            "note": self.note or None,
        }


@dataclass(frozen=True)
class AlarmState:
    """One alarm code as the profile explains it; `active` is true only for the drive's current alarm."""

    code: int
    display: str
    name: str
    clearable: bool | None
    active: bool
    known: bool = True
    manual: ManualNote | None = None  # None for "no alarm"

    def as_json(self) -> dict[str, object]:
        return {
            "code": self.code,
            "display": self.display,
            "name": self.name,
            "active": self.active,
            "clearable": self.clearable,
            "known": self.known,
            "manual": None if self.manual is None else self.manual.as_json(),
        }


def manual_note(profile: Profile, code: int) -> ManualNote:
    """The manual's causes and remedies for an alarm, or why the profile has none to give."""
    table = profile.alarm_causes
    if table is None:
        return ManualNote((), "", f"the {profile.id} profile has no table of the manual's alarm causes")
    note = table.of(code)
    if note is None:
        return ManualNote((), table.source, table.none)
    return ManualNote(note.causes, note.source)


def describe(profile: Profile, code: int, *, active: bool | None = None) -> AlarmState:
    """The profile's name for an alarm code, with the manual's causes; a code the profile does not list is shown
    as unknown, not guessed.

    `active` defaults to "the code is not zero", which is right for the current-alarm register only.
    """
    is_active = code != 0 if active is None else active
    if code == 0:
        return AlarmState(0, "-", "no alarm", None, False)
    known = profile.alarm(code)
    if known is None:
        return AlarmState(
            code,
            f"0x{code:04X}",
            f"unknown alarm (not in the {profile.id} profile)",
            None,
            is_active,
            known=False,
            manual=ManualNote((), "", "not in the profile's alarm list, so the manual's causes cannot be looked up"),
        )
    return AlarmState(code, known.display, known.name, known.clearable, is_active, manual=manual_note(profile, code))


def current(drive: Drive) -> AlarmState:
    """The drive's current alarm. On a drive that shows one alarm record at a time, the current alarm is the
    record its selector names at the selector's 'current' value: any other selection is refused, not read as the
    current alarm (a panel user may have left it on a past record)."""
    selector = _selector(drive.profile)
    code_entry = drive.profile.need_role("alarm_code", FEATURE)
    if selector is None:
        return describe(drive.profile, drive.read_entries([code_entry])[0].raw)
    chosen, code = drive.read_entries([drive.profile.entry(selector.code), code_entry])
    if chosen.raw != selector.current:
        raise VerifyError(
            f"cannot read the current alarm: {selector.code} = {chosen.raw} selects past alarm record {chosen.raw}, "
            f"so {code_entry.code} shows that record; set {selector.code}={selector.current} "
            f"('param set {selector.code}={selector.current}')"
        )
    return describe(drive.profile, code.raw)


def confirmed(drive: Drive) -> AlarmState | None:
    """The drive's alarm when two reads in a row report it (one stray reply is no alarm); None without one or
    where the profile maps no alarm code."""
    if drive.profile.role("alarm_code") is None:
        return None
    state = current(drive)
    return state if state.active and current(drive).code == state.code else None


def history_roles(profile: Profile) -> list[str]:
    roles = [r for r in profile.roles if re.fullmatch(r"alarm_history_\d+", r)]
    return sorted(roles, key=lambda r: int(r.rsplit("_", 1)[1]))


def _selector(profile: Profile) -> RecordSelector | None:
    return profile.alarm_log.select if profile.alarm_log is not None else None


@dataclass(frozen=True)
class Recorded:
    """One value the drive recorded beside an alarm: its meaning, the entry it was read from, the value."""

    meaning: str
    reading: Reading
    text: str  # as shown: '612 rpm', 'DI1 DI5'

    def as_json(self) -> dict[str, object]:
        e = self.reading.entry
        if self.meaning in ("inputs", "outputs"):
            return {"code": e.code, "value": self.reading.raw, "unit": "", "text": self.text}
        return {"code": e.code, "value": as_held(e, self.reading.eng), "unit": e.unit}


@dataclass(frozen=True)
class AlarmRecord:
    """A past alarm in the drive's log: its place (1 = the most recent), the alarm, what was recorded beside it."""

    number: int
    alarm: AlarmState
    recorded: tuple[Recorded, ...] = ()

    def as_json(self) -> dict[str, object]:
        return {
            "record": self.number,
            **self.alarm.as_json(),
            "recorded": {r.meaning: r.as_json() for r in self.recorded},
        }


@dataclass(frozen=True)
class AlarmHistory:
    """The current alarm and the drive's log of past ones (only the records that hold an alarm)."""

    current: AlarmState
    current_recorded: tuple[Recorded, ...]
    records: list[AlarmRecord]
    slots: int  # how many records the drive keeps
    kept_in: str  # where: the entries read ('So-10..So-12') or the selector ('H0B-33 = 1..9')
    excludes_current: bool  # the log holds the alarms before the current one
    source: str = ""
    unverified: str = ""

    def as_json(self) -> dict[str, object]:
        return {
            "current": {
                **self.current.as_json(),
                "recorded": {r.meaning: r.as_json() for r in self.current_recorded},
            },
            "records": [r.as_json() for r in self.records],
            "slots": self.slots,
            "kept_in": self.kept_in,
            "excludes_current": self.excludes_current,
            "source": self.source or None,
            "unverified": self.unverified or None,
        }


def _recorded(profile: Profile, code_entry: Entry, readings: dict[str, Reading]) -> tuple[Recorded, ...]:
    """What the drive recorded beside the alarm in code_entry, in CONTEXT_WORDS order."""
    context = profile.alarm_log.context_of(code_entry.code) if profile.alarm_log is not None else {}
    out: list[Recorded] = []
    for meaning in CONTEXT_WORDS:
        if meaning not in context:
            continue
        r = readings[profile.entry(context[meaning]).code]
        out.append(Recorded(meaning, r, _text(profile, meaning, r)))
    return tuple(out)


def _text(profile: Profile, meaning: str, r: Reading) -> str:
    if meaning in ("inputs", "outputs"):
        group = getattr(profile.io, meaning, None) if profile.io is not None else None
        if group is None:
            return f"0x{r.raw:04X}"
        on = [t.name for t in group.terminals if r.raw >> t.bit & 1]
        return " ".join(on) if on else "none"
    value = as_held(r.entry, r.eng)
    return f"{value} {r.entry.unit}".strip()


def _context_entries(profile: Profile, code_entry: Entry) -> list[Entry]:
    context = profile.alarm_log.context_of(code_entry.code) if profile.alarm_log is not None else {}
    return [profile.entry(c) for c in context.values()]


def history(drive: Drive) -> AlarmHistory:
    """The current alarm and the drive's own log of past alarms, most recent first, with what it recorded beside
    each. A drive that shows one record at a time (alarm_log.select) has each selected in turn, and its selector
    put back as it was, verified, whatever happens."""
    profile = drive.profile
    code_entry = profile.need_role("alarm_code", FEATURE)
    selector = _selector(profile)
    log = profile.alarm_log
    if selector is not None:
        return _selected_history(drive, code_entry, selector)
    roles = history_roles(profile)
    if not roles:
        profile.need_role("alarm_history_1", "alarm history")
    slots = [profile.need_role(r, "alarm history") for r in roles]
    wanted = [code_entry, *_context_entries(profile, code_entry)]
    for e in slots:
        wanted += [e, *_context_entries(profile, e)]
    unique = list({e.code: e for e in wanted}.values())
    readings = {r.entry.code: r for r in drive.read_entries(unique)}
    now = describe(profile, readings[code_entry.code].raw)
    excludes = bool(log and log.excludes_current)
    records = []
    for n, e in enumerate(slots, start=1):
        raw = readings[e.code].raw
        if raw == 0:
            continue
        # Where the log's newest record may be the current alarm itself (it is not kept apart), it is marked so.
        active = n == 1 and not excludes and now.active and raw == now.code
        records.append(AlarmRecord(n, describe(profile, raw, active=active), _recorded(profile, e, readings)))
    kept_in = slots[0].code if len(slots) == 1 else f"{slots[0].code}..{slots[-1].code}"
    return AlarmHistory(
        now,
        _recorded(profile, code_entry, readings) if now.active else (),
        records,
        len(slots),
        kept_in,
        excludes,
        log.source if log else "",
        log.unverified if log else "",
    )


def _selected_history(drive: Drive, code_entry: Entry, selector: RecordSelector) -> AlarmHistory:
    """The records of a drive that shows one at a time. The selector is a display register, not a parameter (no
    EEPROM rule, no journal): it is written as a function is triggered, each write verified by read-back."""
    profile = drive.profile
    select = profile.entry(selector.code)
    wanted = [select, code_entry, *_context_entries(profile, code_entry)]
    records: list[AlarmRecord] = []
    original = selected = drive.read_entries([select])[0].raw
    now_state = describe(profile, 0)
    now_recorded: tuple[Recorded, ...] = ()
    try:
        for n in [selector.current, *range(1, selector.past + 1)]:
            if n != selected:
                drive.write_verified(select, n, selected)
                selected = n
            readings = {r.entry.code: r for r in drive.read_entries(wanted)}
            raw = readings[code_entry.code].raw
            if n == selector.current:
                now_state = describe(profile, raw)
                now_recorded = _recorded(profile, code_entry, readings) if now_state.active else ()
            elif raw:
                alarm = describe(profile, raw, active=False)
                records.append(AlarmRecord(n, alarm, _recorded(profile, code_entry, readings)))
    finally:
        if selected != original:
            drive.write_verified(select, original, selected)
    log = profile.alarm_log
    return AlarmHistory(
        now_state,
        now_recorded,
        records,
        selector.past,
        f"{select.code} = 1..{selector.past}",
        True,
        log.source if log else "",
        log.unverified if log else "",
    )


def clear(drive: Drive) -> AlarmState:
    """Reset the alarm and read it again; VerifyError when it is still active (cause not gone)."""
    drive.trigger("alarm_reset", "alarm clear")
    after = current(drive)
    if after.active:
        why = (
            " (not clearable: needs a power cycle or repair)"
            if after.clearable is False
            else " (its cause is still present)"
        )
        raise VerifyError(f"alarm {after.display} {after.name} is still active after reset{why}")
    return after
