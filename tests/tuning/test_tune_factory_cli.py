"""Identification through the CLI at each drive's factory line settings (issue 16): `sim config --line-baud` makes
the simulator answer at the wire time of the drive's factory baud, and `tune inertia` runs as a user runs it."""

from __future__ import annotations

import pytest

from servotool.model.loader import load_profile
from servotool.motion.deadman import route_of
from tests.motion.test_motion import SETUP

SD25_AT_9600 = (
    "issue 16 item 1 unmet on SD25 at 9600: speed and torque take two requests (10-register limit, "
    "L904 and L916 are 14 apart), 18 samples/s at most, and its torque reads in 1 % steps while 2 rev of "
    "travel allow a few % of rated torque: too uncertain at low and medium loads "
    "(bench/inertia_accuracy.py --profiles)"
)


SDC_AT_9600 = (
    "issue 16 item 2 unmet on SDC at 9600: this load comes out 1.9-2.2 % uncertain against the 2 % limit "
    "(bench/inertia_accuracy.py --profiles: 8 of 14 accepted at 9600), so a host slowed by a busy "
    "machine (real time here) tips it into a refusal; bench/inertia_bound.py: SDC at 9600 reaches 95 % "
    "only with acceleration phases of 3 samples or fewer"
)


@pytest.mark.parametrize(
    "profile",
    [
        pytest.param("sd25", marks=pytest.mark.xfail(reason=SD25_AT_9600, strict=False)),
        pytest.param("sdc", marks=pytest.mark.xfail(reason=SDC_AT_9600, strict=False)),
        "is620p",
        "dsx7e",
    ],
)
def test_identification_through_the_cli_at_the_factory_line_speed(cli, profile):
    """A load of 20 (under about 10 the 1 % torque steps of SD25, SDC and IS620P make the result too uncertain
    within 2 rev at these line speeds: refused, as the bench counts)."""
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
    r = cli("--port", "sim", "--profile", profile, "tune", "inertia", "--yes", "--json", "--dry-run", *ack, *room)
    assert r.code == 0, r.err
    res = r.json()
    assert res["ratio"] == pytest.approx(20.0, abs=max(3 * res["ratio_std"], 0.03 * 21))
    assert res["travel"]["value"] <= (12.0 if room else 2.0)


# At 9600 the travel bounds the moves: a load of 37 with gravity is always too uncertain within 2 rev on SD25
# (4-7 %), a load of 20 now and then on SDC (1.9-2.3 %).
AT_9600 = {
    "sd25": [
        "--load-ratio",
        "37",
        "--friction",
        "0.1",
        "--viscous",
        "0.001",
        "--load-torque",
        "0.4",
        "--brake",
        "on",
        "--seed",
        "8",
    ],
    "sdc": ["--load-ratio", "20", "--friction", "0.05", "--seed", "5"],
}


@pytest.mark.parametrize(
    "profile",
    [
        pytest.param(
            "sd25",
            marks=pytest.mark.xfail(
                strict=False,
                reason="issue 31 item 4, open: on SD25 at 9600 baud the travel a refusal names is not yet proven by "
                "the same check before it is offered; in real time it was refused again at 6.3 % (clean-clone CI run, "
                "load 0.7-1.6)",
            ),
        ),
        "sdc",
    ],
)
def test_at_the_factory_9600_baud_a_refusal_names_the_travel_that_then_identifies(cli, profile):
    """What a user at the factory line speed does: run it, and where it is refused, follow the refusal's advice
    (issue 16: the advice of the old refusals did not help)."""
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
    tune = ("--port", "sim", "--profile", profile, "--no-boost", "tune", "inertia", "--yes", "--json", "--dry-run")
    tune = (*tune, "--no-dead-man")  # at the factory line itself: SD25's is not raised
    r = cli(*tune)
    if r.code == 1 and r.json()["suggested_travel"] is None:
        # Real time: now and then the subsets of a rigid load's log disagree by chance and the uncertainty is widened
        # over the limit; that refusal names the disagreement instead of a travel (more travel need not cure what it
        # suspects). A user runs it again.
        assert "inertia differs" in r.json()["reason"] or "resonance" in r.json()["reason"], r.json()["reason"]
        r = cli(*tune)
    if r.code != 0 or profile == "sd25":
        assert r.code == 1, r.err  # refused (SD25: always, at 4-7 %), not failed otherwise
        travel = r.json()["suggested_travel"]["value"]
        assert travel is not None and travel >= 4.0, r.json()["reason"]
        assert f"--travel {travel:g} " in r.json()["reason"]
        r = cli(*tune, "--travel", str(travel))
        assert r.code == 0, r.err
        assert r.json()["travel"]["value"] <= travel
    res = r.json()
    truth = float(AT_9600[profile][1])
    assert res["ratio"] == pytest.approx(truth, abs=3 * res["ratio_std"])
