"""Each fault kind of a bad line (servotool.sim.faults), at fixed seeds, through the real client path (RtuMaster +
Drive over RTU-over-TCP to the simulated drive): no wrong value is ever returned or written. A short sample of
bench/line_faults.py, which runs every kind at several rates on every profile and operation."""

from __future__ import annotations

import random

import pytest

from servotool.drive import Drive
from servotool.errors import DeviceError, UsageError, VerifyError
from servotool.link.master import RtuMaster
from servotool.link.ports import LinkSettings
from servotool.model.codec import words_to_raw
from servotool.model.loader import load_profile
from servotool.ops import backup
from servotool.sim.faults import KINDS, LineFaults, parse_rates
from servotool.sim.firmware import build_drive
from servotool.sim.server import EmbeddedSim
from tests.frames import plain_read

# Every profile meets several kinds; the repeated and held replies meet the two with single-register parameters
# scattered over the map (the reads a stray reply of the same length stood in for, issue 30).
PROFILE_OF = {"duplicate": "sd25", "stale": "is620p", "echo": "sd25", "burst": "is620p", "unit": "sdc"}
PROFILES = ("dsx7e", "sd25", "is620p", "sdc")


def served(profile_id: str) -> tuple:
    """(profile, simulated drive, sim behind a bad line that starts clean)."""
    profile = load_profile(profile_id)
    drive = build_drive(profile, profile.default_unit, persist=False)
    drive.configure(noise=0.0)  # at rest with no noise, live values hold still and can be judged
    drive.firmware.reconfigure()  # type: ignore[attr-defined]
    return profile, drive, EmbeddedSim([drive], LineFaults())


@pytest.fixture
def line(sim_dir):
    profile, drive, sim = served("dsx7e")
    yield profile, drive, sim
    sim.close()


def truth(sim: EmbeddedSim, drive, entry) -> int:
    """What the drive holds, read by a plain pymodbus client on the drives' own port (behind the bad line), not
    through servotool's link or its recovery."""
    return words_to_raw(entry, plain_read(sim.direct_port, entry.address, entry.words, unit=drive.unit))


def settable(profile) -> list:
    roles = {c.upper() for c in profile.roles.values()}
    return [
        e
        for e in profile.of_class("Pn")
        if e.readable
        and e.writable
        and not e.fields
        and not e.enum
        and not e.bits
        and e.max > e.min
        and e.code.upper() not in roles
    ]


def exercise(profile, sim_drive, sim: EmbeddedSim, link: RtuMaster, seed: int, n: int = 16) -> tuple[int, list[str]]:
    """Reads of random parameters, a monitor's repeated reads and verified writes: (operations that succeeded,
    wrong values accepted)."""
    rng = random.Random(seed)
    drive = Drive(link, profile, profile.default_unit)
    params = [e for e in profile.of_class("Pn") if e.readable]
    live = [e for e in profile.of_class("Un") if e.readable][:6]
    done, wrong = 0, []
    for i in range(n):
        try:
            if i % 4 == 3:
                entry = rng.choice(settable(profile))
                raw = rng.randint(entry.min, entry.max)
                try:
                    result = drive.write_verified(entry, raw)
                except VerifyError as exc:  # a clean error when true: the drive does not hold what was sent
                    if truth(sim, sim_drive, entry) == raw:
                        wrong.append(f"false verify error: {exc}")
                    continue
                readings = [(entry, result.new)]
            elif i % 4 == 2:
                readings = [(r.entry, r.raw) for _ in range(3) for r in drive.read_entries(live)]
            else:
                readings = [(r.entry, r.raw) for r in drive.read_entries(rng.sample(params, 3))]
        except DeviceError:
            continue
        done += 1
        wrong += [f"{e.code}={raw}" for e, raw in readings if truth(sim, sim_drive, e) != raw]
    return done, wrong


@pytest.mark.parametrize("kind", KINDS)
def test_no_fault_kind_makes_the_link_return_a_wrong_value(sim_dir, kind):
    profile, sim_drive, sim = served(PROFILE_OF.get(kind, PROFILES[KINDS.index(kind) % len(PROFILES)]))
    proxy = sim.proxy
    # Copies 0-5 ms after the original: several requests later on loopback, as 0-50 ms are on a real line.
    proxy.set_faults(LineFaults({kind: 0.08 if kind == "burst" else 0.2}, seed=5, late_s=0.15, gap_s=0.005))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.1, retries=2))
    try:
        done, wrong = exercise(profile, sim_drive, sim, link, seed=5, n=16)
    finally:
        link.close()
        sim.close()
    assert proxy.applied.get(kind, 0) >= 2  # the line really was bad
    assert wrong == []
    assert done >= 1  # and it was not all errors


@pytest.mark.parametrize("profile_id", ["is620p", "sd25"])
def test_a_backup_on_a_bad_line_holds_only_what_the_drive_holds(sim_dir, profile_id):
    # The two profiles with single-register parameters scattered over the map: many reads of one length, whose
    # repeated, held or foreign replies could stand in for each other. At this seed every kind of fault meets the
    # backup, which then finishes; the timeout is well above a loaded host's stalls and late replies come after it.
    # A backup that could not finish would say so (a clean error); one that finishes holds the drive's values.
    profile, sim_drive, sim = served(profile_id)
    proxy = sim.proxy
    proxy.set_faults(LineFaults(parse_rates("mixed:8%"), seed=4, late_s=0.45, gap_s=0.005))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.3, retries=3))
    try:
        try:
            taken = backup.take(Drive(link, profile, profile.default_unit)).values
        except DeviceError:
            taken = {}
    finally:
        link.close()
    try:
        wrong = [f"{c}={v}" for c, v in taken.items() if truth(sim, sim_drive, profile.entry(c)) != v]
    finally:
        sim.close()
    assert {"duplicate", "stale", "unit", "late", "burst"} <= set(proxy.applied)  # the line really was bad
    assert wrong == []


def test_a_write_the_drive_acknowledges_but_ignores_is_found_by_its_read_back(line):
    profile, sim_drive, sim = line
    entry = profile.entry("Pn004")
    before = truth(sim, sim_drive, entry)
    sim.proxy.set_faults(LineFaults(ignore_writes=frozenset(entry.addresses)))
    link = RtuMaster(LinkSettings(sim.port, timeout=0.1, retries=2))
    try:
        drive = Drive(link, profile, 1)
        with pytest.raises(VerifyError, match=rf"Pn004: wrote {before + 7}\b.* but the drive reads back {before}\b"):
            drive.write_verified(entry, before + 7)
        drive.write_verified(profile.entry("Pn101"), 225)  # other addresses are written
    finally:
        link.close()
    assert truth(sim, sim_drive, entry) == before and sim.proxy.applied == {"ignored write": 1}


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


def test_ignored_writes_are_named_by_code_or_address():
    from servotool.sim.faults import parse_addresses

    profile = load_profile("dsx7e")
    assert parse_addresses(profile, "Pn008, 0x2004,8197") == {0x2008, 0x2009, 0x2004, 8197}  # Pn008 is a u32
    with pytest.raises(UsageError, match="Pn999"):
        parse_addresses(profile, "Pn999")
