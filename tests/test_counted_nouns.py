"""Counted nouns: one home for the plural (servotool.words)."""

from servotool.words import agree, count


def test_one_is_singular_and_others_plural() -> None:
    assert count(1, "parameter") == "1 parameter"
    assert count(0, "parameter") == "0 parameters"
    assert count(3, "entry") == "3 entries"
    assert count(1, "entry") == "1 entry"
    assert count(2, "axis", "axes") == "2 axes"


def test_the_word_agrees_with_the_count() -> None:
    assert f"Pn004 {agree(1, 'takes', 'take')} effect" == "Pn004 takes effect"
    assert f"Pn004, Pn005 {agree(2, 'takes', 'take')} effect" == "Pn004, Pn005 take effect"
    assert agree(0, "differs", "differ") == "differ"
