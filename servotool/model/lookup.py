"""Finding what the user means: other spellings of codes, common group names, values with units, suggestions.

Codes: the manual's and the panel's spellings of one code are the same key (`H08.00`, `H0800`, `h08-00` are
H08-00; `Pn4`, `PN004` are Pn004); a key two entries share is not used. Groups: case-insensitive, and every
profile answers to the common names in COMMON_GROUPS besides its own.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Iterable
from typing import Protocol, TypeVar


class Entry(Protocol):
    """What lookups read of a profile entry (model.profile.Entry; not imported: profile imports this module)."""

    code: str
    name: str
    description: str
    group: str


E = TypeVar("E", bound=Entry)

_CODE = re.compile(r"([A-Za-z]+?)[-._ ]?([0-9][0-9A-Fa-f]*)(?:[-._ ]([0-9A-Fa-f]+))?")


def code_key(text: str) -> str | None:
    """The spelling-free key of a code ('H08.00' -> 'H800', 'Pn004' -> 'PN4'), None for what is no code."""
    m = _CODE.fullmatch(text.strip())
    if m is None:
        return None
    digits = (m.group(2) + (m.group(3) or "")).upper().lstrip("0") or "0"
    return m.group(1).upper() + digits


def suggest(word: str, candidates: Iterable[str], n: int = 3) -> list[str]:
    """The closest candidates to a mistyped word (case-insensitive), best first."""
    by_upper: dict[str, str] = {}
    for c in candidates:
        by_upper.setdefault(c.upper(), c)
    w = word.upper()
    scored = []
    for c in by_upper:
        ratio = difflib.SequenceMatcher(None, w, c).ratio()
        if ratio >= 0.6:  # ties go to the one with more characters in the same place (Pn1O1 -> Pn101)
            scored.append((ratio + 0.01 * sum(a == b for a, b in zip(w, c, strict=False)), c))
    return [by_upper[c] for _, c in sorted(scored, key=lambda sc: (-sc[0], sc[1]))[:n]]


def did_you_mean(word: str, candidates: Iterable[str]) -> str:
    """'; did you mean X?' (or 'X or Y'), or nothing."""
    found = suggest(word, candidates)
    if not found:
        return ""
    return "; did you mean " + (found[0] if len(found) == 1 else ", ".join(found[:-1]) + " or " + found[-1]) + "?"


# Common group name -> the profile groups that hold such entries (a profile's own ids: dsx7e/sdc/sd25 names, the
# IS620P function-code groups H05..H0C of its manual, section 6.3).
COMMON_GROUPS: dict[str, tuple[str, ...]] = {
    "gain": ("gain", "gains", "autotune", "inertia", "H08", "H09"),
    "speed": ("speed", "motion", "jog", "H06", "H12"),
    "position": ("position", "homing", "H05", "H11"),
    "torque": ("torque", "current", "notch", "H07"),
    "io": ("io", "H03", "H04", "H17"),
    "comm": ("comm", "H0C", "H31"),
    "monitor": ("monitor", "H0B"),
}
# Where a profile has no group for a common name, entries whose name says it.
COMMON_WORDS: dict[str, tuple[str, ...]] = {
    "gain": ("gain",),
    "speed": ("speed",),
    "position": ("position",),
    "torque": ("torque",),
    "io": ("di", "do", "input", "output"),
    "comm": ("communication", "modbus", "rs485", "baud"),
    "monitor": (),
}


def group_ids(own: Iterable[str], name: str) -> tuple[set[str], bool]:
    """The profile groups a group name stands for (case-insensitive; common names too) and whether the name is a
    common one that the profile has no group for (then COMMON_WORDS select by name). Empty: unknown."""
    groups = {g.lower(): g for g in own if g}
    key = name.strip().lower()
    if key in groups:
        return {groups[key]}, False
    if key in COMMON_GROUPS:
        found = {groups[g.lower()] for g in COMMON_GROUPS[key] if g.lower() in groups}
        return found, not found
    return set(), False


_UNIT_ALIASES = {
    "rpm": ("r/min", "rev/min", "min-1", "min^-1", "1/min"),
    "s": ("sec",),
    "%": ("percent",),
    "ms": ("msec",),
    "1/s": ("rad/s", "s-1", "/s"),
}
_NUMBER_UNIT = re.compile(r"([+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*([^\d\s.+-].*)")


def _unit_key(unit: str) -> str:
    u = unit.strip().lower().replace(" ", "").replace("·", "*")
    for canonical, others in _UNIT_ALIASES.items():
        if u in others:
            return canonical
    return u


def split_unit(text: str, unit: str) -> tuple[str, str | None]:
    """'3000rpm' -> ('3000', 'rpm'); text without a unit -> (text, None). The caller checks the unit with
    unit_matches."""
    try:
        float(text)
        return text, None  # a number as it is (1e-300 is no '1' in 'e-300')
    except ValueError:
        pass
    m = _NUMBER_UNIT.fullmatch(text.strip())
    if m is None or (m.group(2).lower().startswith(("x", "b")) and text.strip().lower().startswith(("0x", "0b"))):
        return text, None
    return m.group(1), m.group(2).strip()


def unit_matches(given: str, unit: str) -> bool:
    return bool(unit) and _unit_key(given) == _unit_key(unit)


def enum_value(meanings: dict[int, str], text: str) -> int | None:
    """The value whose meaning the text names: the whole meaning, or a unique start of it (case and
    punctuation ignored); None when none or several match."""

    def norm(s: str) -> str:
        return re.sub(r"[^0-9a-z]+", " ", s.lower()).strip()

    want = norm(text)
    if not want:
        return None
    exact = [k for k, v in meanings.items() if norm(v) == want]
    if exact:
        return exact[0]
    starts = [k for k, v in meanings.items() if norm(v).startswith(want)]
    return starts[0] if len(starts) == 1 else None


def class_name(text: str, classes: Iterable[str]) -> str | None:
    """An entry class given in any case ('pn', 'UN') as the profile spells it, or None."""
    return next((c for c in classes if c.lower() == text.strip().lower()), None)


def group_members(entries: Iterable[E], name: str) -> list[E] | None:
    """The entries a group name stands for (its own id in any case, or a common name), None when the name means
    nothing for these entries."""
    entries = list(entries)
    ids, by_words = group_ids({e.group for e in entries}, name)
    if ids:
        return [e for e in entries if e.group in ids]
    if by_words:
        words = COMMON_WORDS.get(name.strip().lower(), ())
        return [e for e in entries if any(re.search(rf"\b{w}\b", e.name.lower()) for w in words)]
    return None


def search(entries: Iterable[E], words: Iterable[str]) -> list[E]:
    """Entries whose code, name, description or group hold every word (any case; a code in any spelling)."""
    wanted = [w.lower() for w in words if w.strip()]
    found = []
    for e in entries:
        text = f"{e.code} {code_key(e.code) or ''} {e.name} {e.description} {e.group}".lower()
        if all(w in text or (code_key(w) or "#").lower() == (code_key(e.code) or "").lower() for w in wanted):
            found.append(e)
    return found
