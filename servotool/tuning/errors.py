"""The failures tuning's procedures raise, below all of them so that none imports another for its exception class.

An exception that carries one procedure's own result (IdentificationRefused with its identify.Result,
GainSearchFailed with its GainSearch, GainsRolledBack with its StepResponse) is defined beside that result: this
module imports no procedure.
"""

from __future__ import annotations

from servotool.errors import ServoError, UsageError


class IdentificationFailed(ServoError):
    """The motion ran but the result is not trustworthy (or the drive reported failure)."""

    exit_code = 1


class TravelExceeded(IdentificationFailed):
    """The axis moved further than the travel limit; the motion was stopped."""


class TravelNeeded(IdentificationFailed):
    """The line needs more travel (and this time) for the fit's limit than the motion was allowed: said before the
    motion, or after the pilot showed a load lighter than the travel serves (`moved`)."""

    def __init__(self, message: str, travel_rev: float, time_s: float, moved: bool) -> None:
        super().__init__(message)
        self.travel_rev, self.time_s, self.moved = travel_rev, time_s, moved


class MarginRefused(UsageError):
    """The suggested gains would leave too little phase or gain margin."""


class TuneDeclined(ServoError):
    """The operator said no before anything moved."""
