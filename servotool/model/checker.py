"""Collecting profile problems with their location, instead of stopping at the first."""

from __future__ import annotations

from collections.abc import Collection
from typing import Any


class Checker:
    """Collects every problem with its location instead of stopping at the first."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.problems: list[str] = []

    def bad(self, loc: str, msg: str) -> None:
        self.problems.append(f"{self.where}: {loc}: {msg}")

    def known_keys(self, data: dict[Any, Any], allowed: Collection[str], loc: str) -> None:
        """Every key of a mapping that is not an allowed one is a problem."""
        for key in data:
            if key not in allowed:
                self.bad(loc, f"unknown key '{key}'")

    def need(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...]) -> Any:
        if key not in data or data[key] is None:
            self.bad(loc, f"missing required key '{key}'")
            return None
        value = data[key]
        if not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
            self.bad(f"{loc}.{key}", f"expected {kind_name(kind)}, got {value!r}")
            return None
        return value

    def opt(self, data: dict[str, Any], key: str, loc: str, kind: type | tuple[type, ...], default: Any) -> Any:
        if key not in data or data[key] is None:
            return default
        value = data[key]
        if not isinstance(value, kind) or (isinstance(value, bool) and kind not in (bool, (bool,))):
            self.bad(f"{loc}.{key}", f"expected {kind_name(kind)}, got {value!r}")
            return default
        return value

    def choice(self, data: dict[str, Any], key: str, loc: str, allowed: tuple[str, ...], default: str) -> str:
        value = data.get(key, default)
        if value is None:
            return default
        if value not in allowed:
            self.bad(f"{loc}.{key}", f"'{value}' is not one of {', '.join(allowed)}")
            return default
        return str(value)


def kind_name(kind: type | tuple[type, ...]) -> str:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    names = {
        int: "an integer",
        float: "a number",
        str: "a string",
        dict: "a mapping",
        list: "a list",
        bool: "true/false",
    }
    return " or ".join(names.get(k, k.__name__) for k in kinds)


def int_map(chk: Checker, raw: Any, loc: str) -> dict[int, str]:
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        chk.bad(loc, "expected a mapping of integer -> name")
        return {}
    out: dict[int, str] = {}
    for k, v in raw.items():
        if not isinstance(k, int) or isinstance(k, bool):
            chk.bad(loc, f"key {k!r} is not an integer")
            continue
        out[k] = str(v)
    return out
