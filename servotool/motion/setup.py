"""Refusing host motion while the drive lacks the profile's motion_setup settings."""

from __future__ import annotations

from collections.abc import Callable

from servotool.drive import Drive
from servotool.model.profile import Entry
from servotool.model.roles import FEATURE
from servotool.model.setup import check as check_setup_values


def check_setup(
    drive: Drive, feature: str = FEATURE, effective_of: Callable[[list[Entry]], list[int]] | None = None
) -> None:
    """Refuse host motion while the drive lacks the profile's motion_setup settings (one line naming each)."""

    def value_of(entries: list[Entry]) -> list[int]:
        return [r.raw for r in drive.read_entries(entries)]

    check_setup_values(drive.profile, "JOG" if feature == FEATURE else feature, value_of, effective_of)
