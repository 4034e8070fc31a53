"""Counted nouns: one home for the plural (servotool.words)."""

from servotool.words import count


def test_one_is_singular_and_others_plural() -> None:
    assert count(1, "parameter") == "1 parameter"
    assert count(0, "parameter") == "0 parameters"
    assert count(3, "entry") == "3 entries"
    assert count(1, "entry") == "1 entry"
    assert count(2, "axis", "axes") == "2 axes"
