"""Bus scan: line settings to try, unit ranges, and two simulated drives of different profiles found on one line."""

from __future__ import annotations

import pytest

from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings
from servotool.ops.identity import shipped_profiles
from servotool.ops.scan import parse_units, scan, settings_to_try
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


def test_two_drives_of_different_profiles_are_found_and_identified():
    sim = EmbeddedSim(
        [build_drive(load_profile("sd25"), 3, persist=False), build_drive(load_profile("dsx7e"), 6, persist=False)]
    )
    seen: list[int] = []
    try:
        result = scan(
            sim.port,
            list(range(1, 9)),
            [],
            shipped_profiles(),
            timeout=0.1,
            progress=lambda done, _total, _setting: seen.append(done),
        )
    finally:
        sim.close()
    found = {f.unit: f for f in result.found}
    assert sorted(found) == [3, 6] and result.probes == 8 and not result.noise
    assert found[3].best.profile.id == "sd25" and found[3].best.firmware == 100
    assert found[6].best.profile.id == "dsx7e" and found[6].best.model == 0x31
    assert seen[-1] == 8 and seen == sorted(seen)
    row = found[6].as_json()
    assert row["profile"] == "dsx7e" and row["baud"] is None and row["drive_model"] == 0x31


def test_factory_settings_come_first_and_options_narrow():
    profiles = [load_profile(p) for p in ("sdc", "is620p")]
    tried = settings_to_try(profiles)
    assert tried[:2] == [LineSettings(9600, "O", 1, 8), LineSettings(57600, "N", 2, 8)]
    assert len(tried) == len(set(tried)) and LineSettings(115200, "E", 1, 8) in tried
    assert settings_to_try(profiles, [19200], ["8N1", "8e1"]) == [
        LineSettings(19200, "N", 1, 8),
        LineSettings(19200, "E", 1, 8),
    ]
    assert settings_to_try(profiles, None, ["8O1"])[0] == LineSettings(9600, "O", 1, 8)


def test_unit_ranges():
    assert parse_units("1-3,7, 2") == [1, 2, 3, 7]
    for bad in ("0-3", "5-2", "1-300", "a"):
        with pytest.raises(UsageError):
            parse_units(bad)


def test_a_setting_the_port_cannot_open_is_skipped_not_fatal():
    from dataclasses import replace

    from servotool.errors import DeviceError
    from servotool.link.master import RtuMaster

    sim = EmbeddedSim([build_drive(load_profile("sdc"), 2, persist=False)])

    def open_link(settings):
        if settings.line.parity == "E":
            raise DeviceError("cannot open port /dev/fake: parity E")
        return RtuMaster(replace(settings, port=sim.port))

    lines = [LineSettings(9600, "E", 1, 8), LineSettings(9600, "O", 1, 8)]
    try:
        result = scan("/dev/fake", [1, 2], lines, shipped_profiles(), timeout=0.1, open_link=open_link)
        with pytest.raises(DeviceError):
            scan("/dev/fake", [1, 2], lines[:1], shipped_profiles(), timeout=0.1, open_link=open_link)
    finally:
        sim.close()
    assert [(f.unit, f.line, f.best.profile.id) for f in result.found] == [(2, lines[1], "sdc")]
    assert result.unusable == [(lines[0], "cannot open port /dev/fake: parity E")]
