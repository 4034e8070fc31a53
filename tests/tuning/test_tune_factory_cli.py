"""Identification through the CLI at each drive's factory line settings (issue 16): `sim config --line-baud` makes
the simulator answer at the wire time of the drive's factory baud, and `tune inertia` runs as a user runs it."""

from __future__ import annotations

import re

import pytest

from servotool.model.loader import load_profile
from servotool.motion.deadman import route_of
from tests.motion.test_motion import SETUP
from tests.tuning.realtime_cli import near, tune_json


@pytest.mark.parametrize("profile", ["sd25", "sdc", "is620p", "dsx7e"])
def test_identification_through_the_cli_at_the_factory_line_speed(cli, profile):
    """A load of 20 (under about 10 the 1 % torque steps of SD25, SDC and IS620P make the result too uncertain
    within 2 rev at these line speeds: refused, as the bench counts). Real time, judged as a loaded CI holds it
    (realtime_cli): SD25 and SDC at 9600 may name a travel; on virtual time
    test_tune_robustness.py::test_identification_at_each_drives_factory_line_speed judges the 3 sigma."""
    p = load_profile(profile)
    assert (
        cli(
            "sim",
            "config",
            "--profile",
            profile,
            "--load-ratio",
            "20",
            "--friction",
            "0.05",
            "--line-baud",
            str(p.line.baud),
        ).code
        == 0
    )
    for args in SETUP[profile]:
        cmd = (
            ("sim", "reset", "-P", profile, "--power-cycle")
            if args is None
            else ("--port", "sim", "--profile", profile, *args)
        )
        assert cli(*cmd).code == 0
    ack = ["--no-dead-man"] if route_of(p).route == "none" else []
    # DSX7E's 500 ms watchdog lets a dead host's motor run on 1.7 rev at 200 rpm: 2 rev leave no useful speed
    room = ["--travel", "12"] if route_of(p).route == "drive_timeout" else []
    r, res = tune_json(cli, "--port", "sim", "--profile", profile, "tune", "inertia", "--yes", "--dry-run", *ack, *room)
    # the line the identification ran at, in the JSON whatever the outcome: SD25's factory 9600 raised (Po504)
    raised = p.boost.available
    assert res["line"] == {
        "baud": p.boost.to_baud if raised else p.line.baud,
        "factory_baud": p.line.baud,
        "raised": raised,
        "why": None,
    }, res["line"]
    if r.code == 0:
        assert near(res, 20.0), res
        assert res["travel"]["value"] <= (12.0 if room else 2.0)


# At 9600 the travel bounds the moves: a load of 20 is now and then too uncertain within 2 rev on SDC (1.9-2.3 %).
AT_9600 = {
    "sdc": ["--load-ratio", "20", "--friction", "0.05", "--seed", "5"],
}


# SDC only: on SD25 at 9600 the travel a refusal names is not yet proven by the same check before it is offered
# (issue 31 item 4, open); in real time it was refused again at 6.3 %. Its case ran here as a non-strict xfail, which
# no outcome fails, for about 30-50 s a run: its judgement is on virtual time (test_remedy.py's SD25 at 9600).
@pytest.mark.parametrize("profile", ["sdc"])
def test_at_the_factory_9600_baud_a_refusal_names_the_travel_that_then_identifies(cli, profile):
    """What a user at the factory line speed does: run it, and where it names a travel, follow it (issue 16: the
    advice of the old refusals did not help). Real time, judged as a loaded CI holds it (realtime_cli); that the
    travel named then identifies within its 3 sigma is judged on virtual time (test_remedy.py's SD25 at 9600,
    test_budget.py's SDC at 9600)."""
    p = load_profile(profile)
    assert (
        cli(
            "sim",
            "config",
            "--profile",
            profile,
            *AT_9600[profile],
            "--noise",
            "0.002",
            "--line-baud",
            str(p.line.baud),
        ).code
        == 0
    )
    for args in SETUP[profile]:
        cmd = (
            ("sim", "reset", "-P", profile, "--power-cycle")
            if args is None
            else ("--port", "sim", "--profile", profile, *args)
        )
        assert cli(*cmd).code == 0
    tune = ("--port", "sim", "--profile", profile, "--no-boost", "tune", "inertia", "--yes", "--dry-run")
    tune = (*tune, "--no-dead-man")  # at the factory line itself: SD25's is not raised
    r, res = tune_json(cli, *tune)
    named = (res.get("suggested_travel") or {}).get("value") if r.code == 1 else None
    if named is not None:  # before moving, after the pilot, or after the motion: in the words as in the JSON
        assert named > 2.0 and re.search(rf"--travel {named:g}\b", res["reason"]), res["reason"]
        assert res["moved"] in (True, False)
        r, res = tune_json(cli, *tune, "--travel", str(named))
        if r.code == 0:
            assert res["travel"]["value"] <= named
    if r.code == 0:
        assert near(res, float(AT_9600[profile][1])), res
