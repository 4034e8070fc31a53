"""`profiles show --json` carries enough to build a drive's register image without servotool's code."""

from __future__ import annotations

import pytest

from servotool.model.codec import raw_to_words
from servotool.model.loader import builtin_ids, load_profile


def third_party_words(e: dict, raw: int) -> list[int]:
    """Registers of a raw value, from the JSON alone (what another tool would write)."""
    n = e["words"]
    if e["combine"] == "decimal":
        base, rest, parts = 10 ** e["digits"], abs(raw), []
        for _ in range(n - 1):
            parts.append(rest % base)
            rest //= base
        parts.append((-rest if raw < 0 else rest) & 0xFFFF)
        low_first = [p & 0xFFFF for p in parts]
    else:
        value = raw & ((1 << (16 * n)) - 1)
        low_first = [(value >> (16 * i)) & 0xFFFF for i in range(n)]
    return low_first if e["word_order"] == "low_first" else low_first[::-1]


def pack_fields(e: dict, values: dict[str, int]) -> int:
    return sum(values[f["name"]] << f["bit_offset"] for f in e["fields"])


@pytest.mark.parametrize("pid", builtin_ids())
def test_every_entry_can_be_encoded_from_the_json(cli, pid):
    r = cli("profiles", "show", pid, "--json")
    assert r.code == 0, r.err
    profile = load_profile(pid)
    for e in r.json()["entries"]:
        entry = profile.entry(e["code"])
        assert {"word_order", "combine", "words"} <= set(e)
        for raw in {e["min"], e["max"], e["default"] if e["default"] is not None else e["min"]}:
            assert third_party_words(e, raw) == raw_to_words(entry, raw), e["code"]
        if e.get("fields"):
            lows = {f["name"]: f["range"][0] for f in e["fields"]}
            highs = {f["name"]: f["range"][1] for f in e["fields"]}
            assert pack_fields(e, lows) <= pack_fields(e, highs)
            assert all(f["width"] in (4, 8) and set(f) >= {"name", "bit_offset", "range", "enum"} for f in e["fields"])


def test_field_layout_matches_a_manual_example(cli):
    """SD25 Po001 'control mode and direction' is a two-field value: X low byte, Y high byte."""
    (po001,) = [e for e in cli("profiles", "show", "sd25", "--json").json()["entries"] if e["code"] == "Po001"]
    assert [(f["name"], f["bit_offset"], f["width"]) for f in po001["fields"]] == [("X", 0, 8), ("Y", 8, 8)]
    assert pack_fields(po001, {"X": 21, "Y": 1}) == po001["max"] == 0x0115
    assert po001["fields"][0]["enum"]["21"] == "bus"


def test_show_gives_the_identity_section_in_json_and_as_text_at_80_columns(cli):
    ident = cli("profiles", "show", "dsx7e", "--json").json()["identity"]
    assert (ident["firmware"], ident["model"]) == ("Un202", "Un200")
    first = ident["checks"][0]
    assert first["code"] == "Un200" and first["range"] == [0, 0x31] and first["sim"] == 0x31 and first["source"]
    r = cli("profiles", "show", "sd25", env={"COLUMNS": "80"})
    assert r.code == 0 and max(len(line) for line in r.out.splitlines()) <= 80
    assert "identity, checked before the first write (firmware So-00)" in r.out
    assert "So-46" in r.out and "100..9999 (sim 100)" in r.out
    r = cli("profiles", "show", "sd25", "--unverified", env={"COLUMNS": "80"})
    assert "So-46" in r.out and "unverified: encoding" in r.out


def test_show_gives_the_modbus_functions_with_their_lines_or_why_unverified(cli):
    """Issue 33: each code raw sends, answered or not, with the manual's lines or the profile's reason."""
    rows = {f["code"]: f for f in cli("profiles", "show", "sd25", "--json").json()["modbus_functions"]}
    assert sorted(rows) == [1, 2, 3, 4, 5, 6, 15, 16]
    assert rows[3]["answered"] and rows[3]["source"].startswith("L2738") and rows[3]["unverified"] is None
    assert not rows[4]["answered"] and rows[4]["source"] is None and "03, 06 and 16" in rows[4]["unverified"]
    r = cli("profiles", "show", "is620p", "--unverified", env={"COLUMNS": "80"})
    assert r.code == 0 and "Modbus functions" in r.out and "no Modbus chapter" in r.out
    assert max(len(line) for line in r.out.splitlines()) <= 80
