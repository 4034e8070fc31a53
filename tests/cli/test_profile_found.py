"""A profile found, not named (issue 33 item 6): on a real port without --profile, servotool reads every shipped
profile's identity checks once, takes the one profile they fit and says so; none or several is a refusal that lists
the candidates; --profile still decides. Against `sim serve` on RTU over TCP, in its own process."""

from __future__ import annotations

import pytest

from servotool.link.rtu import with_crc
from servotool.model.identity import read_plan
from servotool.model.loader import load_profile

PROFILES = ["dsx7e", "is620p", "sd25", "sdc"]
A_PARAMETER = {"dsx7e": "Pn004", "is620p": "H08-15", "sd25": "Po013", "sdc": "PN17"}


def _identity_requests(profile_id: str) -> list[str]:
    """The -v hex of each request that reads the profile's identity checks."""
    p = load_profile(profile_id)
    assert p.identity is not None
    frames = []
    for start, count, _checks in read_plan(p.identity.checks, p.limits.max_read):
        frame = with_crc(bytes([p.default_unit, 3]) + start.to_bytes(2, "big") + count.to_bytes(2, "big"))
        frames.append(">> " + frame.hex(" "))
    return frames


def _reads(err: str) -> list[str]:
    """The -v requests, a read sent again at once counted once: the link's confirmation of a reply that repeats one
    heard for another read (SD25's So-00 and So-46 both answer 100), not a second look at the identity."""
    sent = [line for line in err.splitlines() if line.startswith(">> ")]
    return [line for i, line in enumerate(sent) if i == 0 or sent[i - 1] != line]


@pytest.mark.parametrize("profile", PROFILES)
def test_the_drive_answering_names_its_profile(cli, sim_serve, profile):
    port = sim_serve("-P", profile)
    p = load_profile(profile)
    code = A_PARAMETER[profile]
    r = cli("-v", "--port", port, "param", "get", code, "--json")
    assert r.code == 0, r.err
    assert r.json()[0]["code"] == code
    found = [line for line in r.err.splitlines() if "found:" in line]
    assert len(found) == 1 and f"{p.model} (profile {profile}) by " in found[0], r.err
    for request in _identity_requests(profile):  # read to find it, not again to check it
        assert _reads(r.err).count(request) == 1, (request, r.err)


def test_the_profile_given_still_decides(cli, sim_serve):
    port = sim_serve("-P", "sd25")
    r = cli("--port", port, "-P", "sd25", "param", "get", "Po013")
    assert r.code == 0 and "found:" not in r.err, r.err
    r = cli("--port", port, "-P", "sdc", "param", "set", "PN17=300")  # the identity check refuses, as before
    assert r.code == 2 and "--profile sd25" in r.err and "found:" not in r.err


def test_a_drive_that_fits_no_profile_is_refused_with_the_candidates(cli, sim_serve):
    assert cli("sim", "config", "-P", "sd25", "--missing", "So-00,So-46").code == 0  # a firmware without them
    port = sim_serve("-P", "sd25")
    r = cli("--port", port, "param", "set", "Po013=3")
    assert r.code == 2 and r.out == ""
    assert len(r.err.strip().splitlines()) == 1, r.err
    assert "fits no profile" in r.err and "--profile" in r.err
    for pid in PROFILES:
        assert f"{pid}: " in r.err
    r = cli("--port", port, "--no-identity-check", "-P", "sd25", "param", "get", "Po013", "--json")
    assert r.code == 0 and r.json()[0]["raw"] != 3  # nothing was written


def test_no_answer_without_a_profile_says_what_was_tried(cli, sim_serve):
    port = sim_serve("-P", "sdc")
    r = cli("--port", port, "-u", "9", "param", "get", "PN1")
    assert r.code == 1 and "no answer from unit 9" in r.err and "--profile" in r.err
    assert len(r.err.strip().splitlines()) == 1, r.err
