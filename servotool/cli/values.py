"""How a value is shown beside what the manual confirms of it: a unit or meaning the manual leaves open is marked
'(unverified)' beside the value, and said why under the table (the profile's unverified_values)."""

from __future__ import annotations

from collections.abc import Iterable

from servotool.cli.render import wrap
from servotool.model.codec import json_text
from servotool.model.profile import Entry, Profile

MARK = "(unverified)"
NAMED = 3  # up to this many marked values are each explained under a table; more are counted


def unit_text(profile: Profile, entry: Entry) -> str:
    """The unit as shown beside a value: '% (unverified)' where the manual leaves the value's scale or meaning open."""
    if not profile.value_unverified(entry):
        return entry.unit
    return f"{entry.unit} {MARK}".strip()


def spoken(profile: Profile, entry: Entry, text: str) -> str:
    """A value with its unit in a sentence ('250 %', '250 % (unverified)')."""
    return f"{text} {unit_text(profile, entry)}".rstrip()


def footnote(profile: Profile, entries: Iterable[Entry]) -> str | None:
    """Why the marked values in a table are unverified: each, or how many and where to read why."""
    marked = list({e.code: e for e in entries if profile.value_unverified(e)}.values())
    if not marked:
        return None
    if len(marked) <= NAMED:
        return "\n".join(wrap(f"{MARK} {e.code}: {profile.value_unverified(e)}") for e in marked)
    return wrap(
        f"{MARK} the manual leaves the unit, scale or meaning of {len(marked)} of these values open: "
        f"'servotool profiles show {profile.id} --unverified' says why"
    )


def json_mark(profile: Profile, entry: Entry) -> str | None:
    """The JSON field value_unverified: why the manual does not confirm this value's scale or meaning, or null."""
    return profile.value_unverified(entry) or None


def texts(entry: Entry, **raws: int | None) -> dict[str, str]:
    """The manual's form of encoded values beside their numbers, as KEY_text fields (old=.., new=..: old_text,
    new_text); nothing for plain numbers."""
    out: dict[str, str] = {}
    for key, raw in raws.items():
        if raw is not None and (text := json_text(entry, raw)) is not None:
            out[f"{key}_text"] = text
    return out
