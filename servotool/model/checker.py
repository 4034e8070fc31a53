"""Collecting profile problems with their location, instead of stopping at the first.

Every value is checked for its type as written: a key given with no value (`scale:` or `scale: null`) is a
problem, not the default, since a default silently put in its place (a scale of 1) shows wrong values."""

from __future__ import annotations

import json
import math
from collections.abc import Collection
from typing import Any


class Checker:
    """Collects every problem with its location instead of stopping at the first."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.problems: list[str] = []

    def bad(self, loc: str, msg: str) -> None:
        self.problems.append(f"{self.where}: {loc}: {msg}" if loc else f"{self.where}: {msg}")

    def known_keys(self, data: dict[Any, Any], allowed: Collection[str], loc: str) -> None:
        """Every key of a mapping that is not an allowed one is a problem."""
        for key in data:
            if key not in allowed:
                self.bad(loc, f"unknown key '{key}'")

    def need(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...]) -> Any:
        """A required value of this kind (a string also non-empty); None after reporting a problem."""
        if key not in data:
            self.bad(loc, f"missing required key '{key}'")
            return None
        return self._typed(data[key], at(loc, key), kind)

    def opt(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...], default: Any) -> Any:
        """An optional value of this kind, default when the key is absent (not when it is given empty)."""
        if key not in data:
            return default
        value = self._typed(data[key], at(loc, key), kind)
        return default if value is None else value

    def whole(
        self,
        data: dict[str, Any],
        key: str,
        loc: str,
        low: int,
        high: int,
        default: int,
        *,
        required: bool = False,
        what: str = "",
    ) -> int:
        """An integer in [low, high] (what: the range's name); default when absent or broken (after reporting it)."""
        if key not in data:
            if required:
                self.bad(loc, f"missing required key '{key}'")
            return default
        value = self._typed(data[key], at(loc, key), int)
        if value is not None and not low <= value <= high:
            self.bad(at(loc, key), f"{value} is outside {low}..{high}" + (f" ({what})" if what else ""))
            return default
        return default if value is None else value

    def choice(
        self,
        data: dict[str, Any],
        key: str,
        loc: str,
        allowed: tuple[str, ...],
        default: str,
        *,
        required: bool = False,
    ) -> str:
        """One of the allowed words; default when absent or broken (after reporting it)."""
        if key not in data:
            if required:
                self.bad(loc, f"missing required key '{key}'")
            return default
        value = data[key]
        if not isinstance(value, str) or value not in allowed:
            self.bad(at(loc, key), f"{shown(value)} is not one of {', '.join(allowed)}")
            return default
        return value

    def _typed(self, value: Any, where: str, kind: type | tuple[type, ...]) -> Any:
        kinds = kind if isinstance(kind, tuple) else (kind,)
        if value is None:
            self.bad(where, f"expected {kind_name(kind)}, got nothing (null)")
            return None
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            self.bad(where, f"expected {kind_name(kind)}, got {shown(value)}")
            return None
        if isinstance(value, float) and not math.isfinite(value):
            self.bad(where, f"expected a finite number, got {shown(value)}")
            return None
        if isinstance(value, str) and not value.strip():
            self.bad(where, "must not be empty")
            return None
        return value


def at(loc: str, key: object) -> str:
    """The location of a key inside loc ("" is the top of the file)."""
    return f"{loc}.{key}" if loc else str(key)


def kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if set(kinds) == {int, float}:
        return "a number"
    names = {
        int: "an integer",
        float: "a number",
        str: "a string",
        dict: "a mapping",
        list: "a list",
        bool: "true/false",
    }
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def shown(value: Any) -> str:
    """A value as the file spells it (null, true, "Hz", ["Hz"]), so the problem line shows what was written."""
    try:
        return json.dumps(value, ensure_ascii=False, default=str)
    except (TypeError, ValueError):
        return repr(value)


def int_map(chk: Checker, raw: Any, loc: str, low: int, high: int) -> dict[int, str]:
    """A mapping of integers in [low, high] to non-empty names (bits, enum values)."""
    if not isinstance(raw, dict) or not raw:
        chk.bad(loc, f"expected a mapping of integer -> name, got {shown(raw)}")
        return {}
    out: dict[int, str] = {}
    for k, v in raw.items():
        if not isinstance(k, int) or isinstance(k, bool):
            chk.bad(loc, f"key {shown(k)} is not an integer")
        elif not low <= k <= high:
            chk.bad(loc, f"key {k} is outside {low}..{high}")
        elif not isinstance(v, str) or not v.strip():
            chk.bad(f"{loc}.{k}", f"expected a name (a non-empty string), got {shown(v)}")
        else:
            out[k] = v
    return out
