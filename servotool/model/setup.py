"""Drive settings host motion needs (profile `motion_setup`): check them before moving; a refusal carries what differs.

A requirement is an entry's whole value (`H02-00 = 0`) or some fields of a two-/four-parameter value
(`Po407.X = 26`, written `X=26` in the profile): only the named fields are compared. servotool never writes them
itself: they change how the drive takes commands from its terminals, so the user sets them on purpose. A refusal
is a SetupRequired carrying the facts; the CLI words the commands that fix it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from servotool.errors import SetupGap, SetupRequired
from servotool.model.codec import decimals, field_index, format_value, parse_value, raw_to_eng
from servotool.model.profile import Entry, Profile, SetupItem


@dataclass(frozen=True)
class Requirement:
    """One motion_setup item resolved against its entry."""

    item: SetupItem
    entry: Entry
    wanted: int  # raw value (only the bits of `fields` count when fields are named)
    fields: tuple[str, ...]  # field names of a field-assignment value, () for the whole value

    @property
    def mask(self) -> int:
        if not self.fields:
            return -1
        width = self.entry.field_width
        return sum(((1 << width) - 1) << (width * field_index(self.entry, f)) for f in self.fields)

    def met(self, raw: int) -> bool:
        return raw & self.mask == self.wanted & self.mask

    def _field(self, raw: int, name: str) -> int:
        width = self.entry.field_width
        return raw >> (width * field_index(self.entry, name)) & ((1 << width) - 1)

    def differences(self, raw: int) -> list[tuple[str, str, str]]:
        """(setting, wanted, now) for each part that differs, values as users type them."""
        if not self.fields:
            return [(self.entry.code, _short(self.entry, self.wanted), _short(self.entry, raw))]
        return [
            (f"{self.entry.code}.{f}", str(self._field(self.wanted, f)), str(self._field(raw, f)))
            for f in self.fields
            if self._field(raw, f) != self._field(self.wanted, f)
        ]

    def assignments(self) -> list[str]:
        """The `param set` arguments that make it so (fields one by one, so the others are kept)."""
        if self.fields:
            return [f"{self.entry.code}.{f}={self._field(self.wanted, f)}" for f in self.fields]
        return [f"{self.entry.code}={_short(self.entry, self.wanted)}"]


def _short(entry: Entry, raw: int) -> str:
    """A value as users type it (no enum name, no bit list)."""
    if entry.format == "dec":
        eng = raw_to_eng(entry, raw)
        return f"{eng:.{decimals(entry)}f}" if isinstance(eng, float) else str(eng)
    if entry.format == "bits":
        return str(raw)
    return format_value(entry, raw)


def requirement(entry: Entry, value: str, item: SetupItem | None = None) -> Requirement:
    """Resolve a value as users type it; UsageError when it is not valid for the entry."""
    text = value.strip()
    parts = [p for p in re.split(r"[\s,]+", text) if p]
    names: tuple[str, ...] = ()
    if entry.format == "digits" and parts and all("=" in p for p in parts):
        names = tuple(entry.fields[field_index(entry, p.partition("=")[0])] for p in parts)
        wanted = parse_value(entry, text, current=0)
    else:
        wanted = parse_value(entry, text)
    return Requirement(item or SetupItem(entry.code, text, "", ""), entry, wanted, names)


def requirements(profile: Profile) -> list[Requirement]:
    return [requirement(profile.entry(i.code), i.value, i) for i in profile.motion_setup]


def unmet(profile: Profile, value_of: Callable[[list[Entry]], list[int]]) -> list[tuple[Requirement, int]]:
    """Requirements whose entry's value (read by value_of, all at once) differs, with that value."""
    reqs = requirements(profile)
    if not reqs:
        return []
    values = value_of([r.entry for r in reqs])
    return [(r, v) for r, v in zip(reqs, values, strict=True) if not r.met(v)]


def gap(req: Requirement, raw: int | None) -> SetupGap:
    """The facts of one requirement for a SetupRequired: what differs from raw (None: set, waiting)."""
    parts = () if raw is None else tuple(req.differences(raw))
    return SetupGap(req.entry.code, parts, tuple(req.assignments()), req.entry.effect == "power_cycle")


def setup_required(
    profile: Profile, feature: str, missing: list[tuple[Requirement, int]], waiting: Sequence[Requirement] = ()
) -> SetupRequired:
    """The refusal for settings that differ (and those set but waiting for a power cycle)."""
    from servotool.model.profile import can_save

    save = profile.persistence.mode != "immediate" and can_save(profile)
    return SetupRequired(feature, [gap(r, raw) for r, raw in missing], [gap(r, None) for r in waiting], save)


def check(
    profile: Profile,
    feature: str,
    value_of: Callable[[list[Entry]], list[int]],
    effective_of: Callable[[list[Entry]], list[int]] | None = None,
) -> None:
    """Refuse host motion (SetupRequired) while any motion_setup setting differs.

    effective_of, where the caller can know it (the simulator), gives the values in effect: a power-cycle
    setting written but not yet in effect is refused too. A real drive reads back the written value.
    """
    missing = unmet(profile, value_of)
    waiting: list[Requirement] = []
    if effective_of is not None:
        done = {r.entry.code for r, _ in missing}
        waiting = [r for r, _ in unmet(profile, effective_of) if r.entry.code not in done]
    if missing or waiting:
        raise setup_required(profile, feature, missing, waiting)
