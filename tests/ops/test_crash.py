"""kill -9 at random points of param restore, param reset, param set --save and run PLAN on SD25 and IS620P over a
slow emulated line: after the next servotool command, the EEPROM switch and every value are what the journal and
the automatic backup say, and no journal record or temporary file is left (issue 14). A short seeded sample of
bench/kill_storm.py, which runs the long storm and prints the share of kills recovered."""

from __future__ import annotations

import random
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench"))
from kill_storm import Storm


# Every operation on one of the two drives here (the bench runs the full matrix), each kill timed within 0.4 s
# of the operation's first write, where it can leave the switch changed or a restore half done.
@pytest.mark.parametrize(("profile", "ops"), [("sd25", ("restore", "save")), ("is620p", ("reset", "plan"))])
def test_every_kill_is_recovered_by_the_next_command(profile, ops, tmp_path, sim_dir):
    storm = Storm(profile, 19200, tmp_path / "storm")
    rng = random.Random(f"crash-{profile}")
    failures = []
    for op in ops:
        good, why = storm.kill_at(op, rng.uniform(0, 0.4), targeted=True)
        if not good:
            failures.append(f"{op}: {why}")
    assert not failures, failures
