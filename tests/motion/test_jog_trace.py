"""A JOG leaves the drive's parameters as it found them (issue 14 defect 6): its JOG speed is put back."""

from __future__ import annotations

import pytest

# IS620P's segment route (profiles/is620p.yaml motion_setup)
IS620P_SETUP = ["H02-00=1", "H05-00=2", "H05-02=10000", "H11-00=0", "H0C-09=1", "H17-00=1", "H17-02=28"]


@pytest.mark.parametrize(("profile", "setup"), [("dsx7e", []), ("is620p", IS620P_SETUP)])
def test_a_jog_leaves_no_trace_in_the_drives_settings(cli, tmp_path, profile, setup):
    if setup:
        assert cli("--port", "sim", "-P", profile, "param", "set", *setup).code == 0
    before = tmp_path / "before.yaml"
    assert cli("--port", "sim", "-P", profile, "param", "backup", "-o", str(before)).code == 0
    r = cli("--port", "sim", "-P", profile, "jog", "--speed", "370", "--time", "0.3")
    assert r.code == 0, r.err
    r = cli("--port", "sim", "-P", profile, "param", "diff", str(before), "--json")
    assert r.code == 0 and r.json()["differences"] == [], r.out
