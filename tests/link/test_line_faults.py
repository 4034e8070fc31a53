"""Each fault kind of a bad line (servotool.sim.faults), at fixed seeds, through the real client path (RtuMaster +
Drive over RTU-over-TCP to the simulated drive): no wrong value is ever returned or written."""

from __future__ import annotations

import random

import pytest

from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.codec import words_to_raw
from servotool.model.loader import load_profile
from servotool.sim.faults import KINDS, LineFaults, parse_rates
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim


@pytest.fixture
def line(sim_dir):
    """(profile, simulated drive, sim behind a bad line that starts clean)."""
    profile = load_profile("dsx7e")
    drive = build_drive(profile, 1, persist=False)
    sim = EmbeddedSim([drive], LineFaults())
    yield profile, drive, sim
    sim.close()


def truth(sim: EmbeddedSim, drive, entry) -> int:
    with sim.lock:
        return words_to_raw(entry, drive.read(entry.address, entry.words))


def exercise(profile, sim_drive, sim: EmbeddedSim, link: RtuMaster, seed: int) -> tuple[int, list[str]]:
    """Reads and verified writes of random parameters: (operations that succeeded, wrong values accepted)."""
    rng = random.Random(seed)
    drive = Drive(link, profile, 1)
    params = [e for e in profile.of_class("Pn") if e.readable]
    settable = [
        e
        for e in params
        if e.writable
        and not e.fields
        and not e.enum
        and not e.bits
        and e.max > e.min
        and e.code not in profile.roles.values()
    ]
    done, wrong = 0, []
    for i in range(16):
        try:
            if i % 4 == 3:
                entry = rng.choice(settable)
                result = drive.write_verified(entry, rng.randint(entry.min, entry.max))
                readings = [(entry, result.new)]
            else:
                readings = [(r.entry, r.raw) for r in drive.read_entries(rng.sample(params, 3))]
        except DeviceError:
            continue
        done += 1
        wrong += [f"{e.code}={raw}" for e, raw in readings if truth(sim, sim_drive, e) != raw]
    return done, wrong


@pytest.mark.parametrize("kind", KINDS)
def test_no_fault_kind_makes_the_link_return_a_wrong_value(line, kind):
    profile, sim_drive, sim = line
    sim.proxy.set_faults(LineFaults({kind: 0.3}, seed=7, late_s=0.15))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.1, retries=2))
    try:
        done, wrong = exercise(profile, sim_drive, sim, link, seed=3)
    finally:
        link.close()
    assert sim.proxy.applied.get(kind, 0) >= 3  # the line really was bad
    assert wrong == []
    assert done >= 8  # and the retries still got most operations through


def test_an_echoing_adapter_on_a_bad_line_is_found_and_never_taken_for_the_drive(line):
    profile, sim_drive, sim = line
    sim.proxy.set_faults(LineFaults(parse_rates("mixed:20%"), seed=11, late_s=0.15, echo=True))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.1, retries=2, echo=None))
    try:
        done, wrong = exercise(profile, sim_drive, sim, link, seed=5)
    finally:
        link.close()
    assert wrong == [] and done >= 8


def test_a_trigger_without_an_acknowledgement_is_sent_once(line):
    profile, _sim_drive, sim = line
    sent: list[bytes] = []
    link = RtuMaster(
        LinkSettings(sim.port, timeout=0.1, retries=2),
        trace=lambda sending, data: sent.append(data) if sending else None,
    )
    sim.proxy.set_faults(LineFaults({"drop": 1.0}))
    try:
        with pytest.raises(DeviceError, match=r"Fn030.*may or may not have run; not sent again"):
            Drive(link, profile, 1).trigger("alarm_reset", "alarm clear")
    finally:
        link.close()
    assert len(sent) == 1


def test_a_drive_slower_than_the_timeout_gives_a_clean_error_then_recovers(line):
    profile, sim_drive, sim = line
    entry = profile.entry("Pn004")
    sim.proxy.set_faults(LineFaults(response_delay_s=0.15))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.1, retries=1))
    try:
        with pytest.raises(DeviceError, match=r"no response within 0\.1 s after 2 tries"):
            Drive(link, profile, 1).read_entries([entry])
        sim.proxy.set_faults(LineFaults())
        assert Drive(link, profile, 1).read_entries([entry])[0].raw == truth(sim, sim_drive, entry)
    finally:
        link.close()


def test_the_same_seed_damages_the_same_replies(line):
    profile, _sim_drive, sim = line
    applied = []
    for _ in range(2):
        sim.proxy.applied.clear()
        sim.proxy.set_faults(LineFaults(parse_rates("mixed:30%"), seed=4, late_s=0.05))
        link = RtuMaster(LinkSettings(sim.port, timeout=0.2, retries=2))
        try:
            for _ in range(10):
                link.read(1, profile.entry("Pn004").address, 1)
        except DeviceError:
            pass
        finally:
            link.close()
        applied.append(dict(sim.proxy.applied))
    assert applied[0] == applied[1] and sum(applied[0].values()) > 0


@pytest.mark.parametrize("text", ["crc", "crc:x", "bogus:5%", "crc:150%", "crc:60%,drop:60%"])
def test_bad_fault_specs_are_usage_errors(text):
    with pytest.raises(UsageError):
        LineFaults(parse_rates(text))
