"""Counted nouns in messages ('1 entry', '2 entries'): the one home of the plural, for the library's own words and
the CLI's alike."""

from __future__ import annotations

IRREGULAR = {"entry": "entries"}


def count(n: int, noun: str, plural: str | None = None) -> str:
    """'1 parameter', '2 parameters', '3 entries'."""
    return f"{n} {noun if n == 1 else plural or IRREGULAR.get(noun, noun + 's')}"
