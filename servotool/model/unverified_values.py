"""Values whose scale or meaning the manual does not confirm (profile section `unverified_values`).

An entry's `unverified` gives every doubt about it (its address, default, effect, ...); this section names the
entries whose *value* a user should not take as fact: a unit or scale the manual does not print, a meaning it
leaves open, a word order it does not state. Wherever such a value is shown, it is marked, with this reason.
"""

from __future__ import annotations

from typing import Any

from servotool.model.checker import Checker
from servotool.model.profile import Entry


def parse_unverified_values(chk: Checker, raw: Any, entries: dict[str, Entry]) -> dict[str, str]:
    """Entry code (upper case) -> why its value's scale or meaning is unverified."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        chk.bad("unverified_values", "expected a mapping of entry code -> reason")
        return {}
    out: dict[str, str] = {}
    for code, reason in raw.items():
        entry = entries.get(str(code).upper())
        if entry is None:
            chk.bad(f"unverified_values.{code}", f"names unknown entry {code!r}")
        elif not isinstance(reason, str) or not reason.strip():
            chk.bad(f"unverified_values.{code}", "expected the reason, as text")
        else:
            out[entry.code.upper()] = reason.strip()
    return out
