"""Counted nouns in messages ('1 entry', '2 entries') and the words that agree with them ('takes', 'take'): the one
home of the plural, for the library's own words and the CLI's alike."""

from __future__ import annotations

IRREGULAR = {"entry": "entries"}


def count(n: int, noun: str, plural: str | None = None) -> str:
    """'1 parameter', '2 parameters', '3 entries'."""
    return f"{n} {noun if n == 1 else plural or IRREGULAR.get(noun, noun + 's')}"


def agree(n: int, one: str, many: str) -> str:
    """The word that agrees with n things: agree(1, 'takes', 'take') is 'takes', agree(2, 'it', 'they') 'they'."""
    return one if n == 1 else many
