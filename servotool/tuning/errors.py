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


class MarginRefused(UsageError):
    """The suggested gains would leave too little phase or gain margin."""


class TuneDeclined(ServoError):
    """The operator said no before anything moved."""
