"""The simulated drive's alarm log: the code a latched alarm reports and the history it enters once, with what the
drive records beside it (the profile's alarm_log: speed, bus voltage, current, run time, terminals)."""

from __future__ import annotations

from typing import Any

from servotool.model.profile import Profile
from servotool.sim.registers import RegisterBank

HISTORY_LENGTH = 10  # as many as the longest documented log (IS620P: the current fault and 9 before it)
UNLISTED_ALARM_CODE = 0xFF  # a trip the profile lists no alarm for: outside its list, so it shows as unknown


class AlarmLog:
    """Alarm codes by kind and the fault history, kept in the state file like a drive's fault log."""

    def __init__(self, profile: Profile, bank: RegisterBank) -> None:
        self.profile = profile
        self.bank = bank
        self.recorded = False  # whether the alarm latched now is already in the history
        self.new_record = False  # a record entered since the monitors were last refreshed

    @property
    def history(self) -> list[Any]:
        """Latest first: each a record {code, time, speed, ...} (a bare code in state files of older versions)."""
        return self.bank.extra.setdefault("alarm_history", [])

    def records(self) -> list[dict[str, Any]]:
        """The history as records, latest first."""
        return [r if isinstance(r, dict) else {"code": int(r)} for r in self.history]

    def past(self, active: bool) -> list[dict[str, Any]]:
        """The records a drive shows as past alarms: where its log keeps the current alarm apart (alarm_log
        excludes_current), the ones before the alarm latched now."""
        records = self.records()
        log = self.profile.alarm_log
        if active and self.recorded and log is not None and log.excludes_current:
            return records[1:]
        return records

    def code(self, kind: str | None) -> int:
        """The code the drive reports for a latched alarm of this kind (0: none latched)."""
        if kind is None:
            return 0
        # Rather than borrowing some unrelated alarm's name, an unlisted kind reports a code the profile lacks.
        alarm = self.profile.alarm_of_kind(kind)
        return alarm.code if alarm is not None else UNLISTED_ALARM_CODE

    def record(self, kind: str | None, context: dict[str, float] | None = None) -> None:
        """Enter the latched alarm in the history once (it stays latched until a reset clears it), with what the
        drive records beside it."""
        code = self.code(kind)
        if code and not self.recorded:
            self.history.insert(0, {"code": code, **(context or {})})
            del self.history[HISTORY_LENGTH:]
            self.bank.save()
            self.recorded = True
            self.new_record = True
