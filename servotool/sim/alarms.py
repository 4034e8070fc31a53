"""The simulated drive's alarm log: the code a latched alarm reports and the history it enters once."""

from __future__ import annotations

from servotool.model.profile import Profile
from servotool.sim.registers import RegisterBank

HISTORY_LENGTH = 8
UNLISTED_ALARM_CODE = 0xFF  # a trip the profile lists no alarm for: outside its list, so it shows as unknown


class AlarmLog:
    """Alarm codes by kind and the fault history, kept in the state file like a drive's fault log."""

    def __init__(self, profile: Profile, bank: RegisterBank) -> None:
        self.profile = profile
        self.bank = bank
        self.recorded = False  # whether the alarm latched now is already in the history

    @property
    def history(self) -> list[int]:
        """Latest first."""
        return self.bank.extra.setdefault("alarm_history", [])

    def code(self, kind: str | None) -> int:
        """The code the drive reports for a latched alarm of this kind (0: none latched)."""
        if kind is None:
            return 0
        # Rather than borrowing some unrelated alarm's name, an unlisted kind reports a code the profile lacks.
        alarm = self.profile.alarm_of_kind(kind)
        return alarm.code if alarm is not None else UNLISTED_ALARM_CODE

    def record(self, kind: str | None) -> None:
        """Enter the latched alarm in the history once (it stays latched until a reset clears it)."""
        code = self.code(kind)
        if code and not self.recorded:
            self.history.insert(0, code)
            del self.history[HISTORY_LENGTH:]
            self.bank.save()
            self.recorded = True
