"""Which Modbus function codes a drive answers, by its manual: a profile's `modbus_functions` section.

The one home for it: `raw` warns before a code the manual does not list and words a refusal with the reason, the
simulated drive answers exception 01 to every code outside `answered`, `profiles show` prints the notes. A code is
documented (the manual lines that list it) or unverified (the section's reason); `assumed` codes are answered
although no manual line lists them (a drive whose volume has no Modbus chapter still needs FC03 to be reached).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from servotool.model.checker import Checker, int_map, shown

# What `raw` can send: coils and discrete inputs, holding and input registers, single and multiple writes.
RAW_FUNCTIONS = (1, 2, 3, 4, 5, 6, 15, 16)
NAMES = {
    1: "read coils",
    2: "read discrete inputs",
    3: "read holding registers",
    4: "read input registers",
    5: "write single coil",
    6: "write single register",
    15: "write multiple coils",
    16: "write multiple registers",
}
KEYS = {"documented", "assumed", "unverified"}
UNSAID = "the profile does not say which Modbus functions its manual documents"


@dataclass(frozen=True)
class ModbusFunctions:
    """documented: code -> the manual's lines that list it; assumed: codes answered without such a line; unverified:
    why every other code (and each assumed one) is not known from the manual."""

    documented: dict[int, str] = field(default_factory=dict)
    assumed: tuple[int, ...] = (3, 6, 16)
    unverified: str = UNSAID

    @property
    def answered(self) -> frozenset[int]:
        """The codes the drive answers (the simulated one serves these, exception 01 to the rest)."""
        return frozenset(self.documented) | frozenset(self.assumed)

    def note(self, fc: int) -> str | None:
        """Why this code is unverified on this drive; None where the manual documents it."""
        if fc in self.documented:
            return None
        said = "answered as assumed" if fc in self.assumed else "not in the manual"
        return f"{said}: {self.unverified}"


def parse_modbus_functions(chk: Checker, raw: Any, write_multiple: bool) -> ModbusFunctions:
    """The `modbus_functions` mapping {documented: {code: lines}, assumed: [codes], unverified: why}; problems go
    to the checker. FC03 must be answered, and FC16 exactly where limits.write_multiple says."""
    loc = "modbus_functions"
    if not isinstance(raw, dict):
        chk.bad(loc, f"expected a mapping {{documented, assumed, unverified}}, got {shown(raw)}")
        return ModbusFunctions()
    before = len(chk.problems)
    chk.known_keys(raw, KEYS, loc)
    documented = int_map(chk, raw["documented"], f"{loc}.documented", 1, 127) if "documented" in raw else {}
    assumed_raw = raw.get("assumed", [])
    assumed: tuple[int, ...] = ()
    if not isinstance(assumed_raw, list) or not all(type(c) is int for c in assumed_raw):
        chk.bad(f"{loc}.assumed", f"expected a list of function codes, got {shown(assumed_raw)}")
    else:
        assumed = tuple(assumed_raw)
        if both := sorted(set(assumed) & set(documented)):
            chk.bad(f"{loc}.assumed", f"{', '.join(map(str, both))} documented already: a code is one or the other")
    for key, codes in (("documented", documented), ("assumed", assumed)):
        for code in codes:
            if code not in RAW_FUNCTIONS:
                chk.bad(f"{loc}.{key}", f"function {code} is not one raw sends ({', '.join(map(str, RAW_FUNCTIONS))})")
    unverified = chk.need(raw, "unverified", loc, str) or UNSAID
    found = ModbusFunctions(documented, assumed, unverified)
    if len(chk.problems) > before:  # what the broken part names is not known: its own problem says what to fix
        return found
    if 3 not in found.answered:
        chk.bad(loc, "FC03 is neither documented nor assumed: every feature reads holding registers")
    if write_multiple != (16 in found.answered):
        said = "answered" if 16 in found.answered else "neither documented nor assumed"
        chk.bad(loc, f"FC16 is {said}, but limits.write_multiple is {str(write_multiple).lower()}")
    return found


def functions_json(functions: ModbusFunctions) -> list[dict[str, object]]:
    """Each code raw sends, with whether the drive answers it and the manual's lines or why it is unverified."""
    return [
        {
            "code": fc,
            "name": NAMES[fc],
            "answered": fc in functions.answered,
            "source": functions.documented.get(fc),
            "unverified": functions.note(fc),
        }
        for fc in RAW_FUNCTIONS
    ]
