"""What a drive's manual says about its alarms beyond their names (profile sections `alarm_causes`, `alarm_log`).

`alarm_causes`: the manual's cause-and-remedy table, per alarm code, with its lines; for an alarm it gives none, the
section's `none` says so (never a cause the manual does not print). `alarm_log`: what the drive keeps of its past
alarms beyond the codes in the alarm_history_N roles: the values recorded with each alarm (speed, bus voltage, ...),
and, on a drive that shows one record at a time, the entry that selects it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

# What a drive records with an alarm, by meaning (the simulator fills them in, the CLI labels them).
CONTEXT_KEYS = ("time", "speed", "bus_voltage", "current", "current_u", "current_v", "inputs", "outputs")


@dataclass(frozen=True)
class CauseRemedy:
    cause: str
    remedy: str


@dataclass(frozen=True)
class AlarmNote:
    """The manual's causes and remedies for one or more alarm codes (the manual groups some)."""

    codes: tuple[int, ...]
    causes: tuple[CauseRemedy, ...]
    source: str
    unverified: str = ""


@dataclass(frozen=True)
class AlarmCauses:
    """The manual's cause-and-remedy table: where it is, what it says of alarms it leaves out, its items."""

    source: str
    none: str
    notes: tuple[AlarmNote, ...] = ()

    def of(self, code: int) -> AlarmNote | None:
        return next((n for n in self.notes if code in n.codes), None)


@dataclass(frozen=True)
class RecordSelector:
    """A drive that shows one alarm record at a time: write `current` or 1..past to `code`, then read the record."""

    code: str
    current: int
    past: int


@dataclass(frozen=True)
class AlarmLog:
    """What the drive keeps with its alarm records (context: record code -> meaning -> entry code)."""

    source: str
    context: dict[str, dict[str, str]] = field(default_factory=dict)
    select: RecordSelector | None = None
    excludes_current: bool = False  # the newest past record is the alarm before the current one
    unverified: str = ""

    def context_of(self, code: str) -> dict[str, str]:
        return self.context.get(code.upper(), {})
