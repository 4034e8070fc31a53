"""The simulated drive's own inertia identification, run by a host over a link as `tune inertia --method drive`
runs it: trigger, watch the status word, read the inertia ratio it stored."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.model.loader import load_profile
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink

FEATURE = "drive-side identification test"
IDENTIFYING = 1 << 5  # DSX7E status word bit 5


def drive_with_load(load_ratio: float) -> tuple[Drive, VirtualClock]:
    clock = VirtualClock(10.0)
    sim = build_drive(load_profile("dsx7e"), 1, clock, persist=False)
    sim.configure(load_ratio=load_ratio, noise=0.0)
    sim.firmware.reconfigure()
    return Drive(VirtualLink([sim], clock), sim.profile, 1), clock


def status(d: Drive) -> int:
    return d.read_role("servo_status", FEATURE).raw


def wait_while_identifying(d: Drive, clock: VirtualClock, limit_s: float = 10.0) -> None:
    for _ in range(round(limit_s / 0.05)):
        clock.advance(0.05)
        if not status(d) & IDENTIFYING:
            return
    raise AssertionError("identification did not end")


def load_ratio(d: Drive) -> float:
    return d.profile.load_ratio_from_param(d.read_role("inertia_ratio", FEATURE).eng)


@pytest.mark.parametrize("true_ratio", [1.0, 8.0])
def test_the_identification_measures_the_load_and_stores_the_ratio(sim_dir, true_ratio):
    d, clock = drive_with_load(true_ratio)
    d.trigger("inertia_id", FEATURE)
    clock.advance(0.05)
    assert status(d) & IDENTIFYING
    wait_while_identifying(d, clock)
    assert d.read_role("alarm_code", FEATURE).raw == 0
    assert load_ratio(d) == pytest.approx(true_ratio, abs=0.5)  # within half a motor inertia


def test_more_travel_than_allowed_fails_with_the_identification_alarm(sim_dir):
    d, clock = drive_with_load(50.0)  # a heavy load travels far before it reaches the top speed
    d.write_verified(*d.parse_assignment("Pn515=1"))
    before = load_ratio(d)
    d.trigger("inertia_id", FEATURE)
    wait_while_identifying(d, clock)
    code = d.profile.alarm_of_kind("inertia_id_failed").code
    assert d.read_role("alarm_code", FEATURE).raw == code
    d.trigger("alarm_reset", FEATURE)
    assert d.read_role("alarm_history_1", FEATURE).raw == code  # in the log, once no longer the current fault
    assert load_ratio(d) == before


def test_an_aborted_identification_stops_and_changes_nothing(sim_dir):
    d, clock = drive_with_load(4.0)
    before = load_ratio(d)
    d.trigger("inertia_id", FEATURE)
    clock.advance(0.1)
    assert status(d) & IDENTIFYING
    d.trigger("inertia_id", FEATURE, 0)
    assert not status(d) & IDENTIFYING and d.read_role("alarm_code", FEATURE).raw == 0
    clock.advance(1.0)
    assert load_ratio(d) == before
