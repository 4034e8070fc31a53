"""Each profile says which Modbus function codes its manual documents, with the lines, and why the rest are
unverified (issue 33): the lines it names print those codes, and the cross-checks refuse a contradiction."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest
import yaml

from servotool.model.loader import builtin_dir, builtin_ids, load_profile
from servotool.model.modbus_functions import RAW_FUNCTIONS
from servotool.model.schema import parse_profile

MANUALS = Path("/work/shared/manuals")
MANUAL_OF = {"sd25": "sd25-ethercat-modbus-manual.zh.txt", "sdc": "sdc-ethercat-rs485-manual.zh.txt"}


@pytest.mark.parametrize("pid", sorted(MANUAL_OF))
def test_each_documented_code_is_printed_on_the_lines_the_profile_names(pid):
    """The first line named for a code starts with that code as the manual prints it (16 or hex 10)."""
    manual = MANUALS / MANUAL_OF[pid]
    if not manual.exists():
        pytest.skip(f"{manual} is not on this machine")
    lines = manual.read_text(encoding="utf-8").splitlines()
    documented = load_profile(pid).modbus_functions.documented
    assert set(documented) == {3, 6, 16}
    for code, source in documented.items():
        first = int(re.search(r"L(\d+)", source).group(1))
        assert lines[first - 1].split()[0] in (f"{code:02d}", f"{code:02X}"), (code, lines[first - 1])


def test_every_shipped_profile_answers_what_its_features_need_and_notes_the_rest():
    for pid in builtin_ids():
        found = load_profile(pid).modbus_functions
        assert found.answered == {3, 6, 16}, pid
        for fc in RAW_FUNCTIONS:
            note = found.note(fc)
            assert (note is None) == (fc in found.documented), (pid, fc)
            if note is not None:
                assert found.unverified in note and note.startswith("answered as assumed") == (fc in found.assumed)
    assert load_profile("is620p").modbus_functions.documented == {}  # its volume has no Modbus chapter


def _problems(mutate) -> list[str]:
    data = copy.deepcopy(yaml.safe_load((builtin_dir() / "sd25.yaml").read_text(encoding="utf-8")))
    mutate(data)
    profile, problems = parse_profile(data, "sd25.yaml")
    assert profile is None
    return problems


def test_a_profile_contradicting_itself_is_refused_in_one_line():
    def no_fc16(d):
        del d["modbus_functions"]["documented"][16]

    assert _problems(no_fc16) == [
        "sd25.yaml: modbus_functions: FC16 is neither documented nor assumed, but limits.write_multiple is true"
    ]

    def no_fc03(d):
        del d["modbus_functions"]["documented"][3]

    assert _problems(no_fc03) == [
        "sd25.yaml: modbus_functions: FC03 is neither documented nor assumed: every feature reads holding registers"
    ]


def test_without_the_section_the_features_codes_are_assumed_and_unverified():
    data = yaml.safe_load((builtin_dir() / "sdc.yaml").read_text(encoding="utf-8"))
    del data["modbus_functions"]
    data["limits"]["write_multiple"] = False
    profile, problems = parse_profile(data, "sdc.yaml")
    assert profile is not None and not problems
    assert profile.modbus_functions.answered == {3, 6}
    assert "does not say" in profile.modbus_functions.note(3)
