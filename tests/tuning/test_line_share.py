"""The identification's requests by kind (issue 16 item 1: its sample rate against what the line carries), on
virtual time: no segment re-arm or setting write a move does not need, a drive watchdog fed late but in time, and the
dead-man bound kept. bench/line_budget.py prints the same counts over more machines."""

from __future__ import annotations

import itertools

import pytest

from servotool.motion import deadman
from servotool.motion.jogger import Jogger
from servotool.tuning.tune import TuneRequest, tune_inertia
from tests.tuning.test_tune_robustness import set_up


def _record(d):
    """Every request on d's link as (time, 'R'/'W', address, values or count)."""
    log: list[tuple[float, str, int, object]] = []
    link, read, write = d.link, d.link.read, d.link.write

    def rec_read(unit, address, count, **kw):
        log.append((link.clock.now(), "R", address, count))
        return read(unit, address, count, **kw)

    def rec_write(unit, address, values, **kw):
        log.append((link.clock.now(), "W", address, list(values)))
        return write(unit, address, values, **kw)

    link.read, link.write = rec_read, rec_write
    return log


def test_is620p_identification_writes_no_segment_re_arm_or_setting_it_does_not_need(sim_dir, monkeypatch):
    """The segment route re-armed its segment on every beat (two writes), read the speed parameter before every move
    and wrote speed and ramp on their own: a quarter of the line at 19200. Now a move's settings and displacement go
    in one request, a re-arm only where the running segment would end, and each segment stays within the
    dead-man's bound."""
    sim, d, clock = set_up("is620p", 57600, load_ratio=10.0, friction=0.05, noise=0.002, seed=1)
    d.dead_man_waived = False
    re_arms = []
    resend = Jogger._resend_command
    monkeypatch.setattr(Jogger, "_resend_command", lambda self: (re_arms.append(clock.now()), resend(self)))
    log = _record(d)
    tune_inertia(d, TuneRequest(dry_run=True), clock=clock)
    p = d.profile
    distance, speed, ramp, start = (p.entry(c) for c in ("H11-12", "H11-14", "H11-15", "H31-00"))
    assert re_arms == []  # each identification move's ramp is shorter than two beats
    moves = [v for _t, op, a, v in log if op == "W" and a == start.address and v == [3]]
    assert len(moves) >= 8
    alone = [a for _t, op, a, v in log if op == "W" and a in (speed.address, ramp.address)]
    assert len(alone) <= 2  # only the put-back at the end: a dithered cycle's shorter ramp at the
    # same speed goes with the speed and the move's displacement in one request (H11-12..H11-15)
    reads = [a for _t, op, a, _v in log if op == "R" and a == speed.address]
    assert len(reads) <= 2  # the snapshot and the put-back, not one a move
    # Every displacement stays within the dead-man's segment at the speed and ramp it runs with (no stop needed).
    units = sim.bank.effective_value("H05-02") or 10000
    v_rpm = ramp_ms = 0.0
    for _t, op, a, v in log:
        if op != "W" or a != distance.address:
            continue
        if len(v) == 4:
            v_rpm, ramp_ms = v[2], v[3]
        rev = abs(((v[1] << 16) | v[0]) - (1 << 32 if v[1] & 0x8000 else 0)) / units
        assert rev <= deadman.segment_rev(v_rpm, 0.1, ramp_ms, sim.profile.ramp_rpm()) + 1e-4
    assert sim.firmware.plant.alarm is None


def test_dsx7e_beats_come_at_the_last_safe_moment_and_the_watchdog_never_starves(sim_dir):
    """DSX7E's watchdog (Pn620, 500 ms) was fed every third of it: 1.6 beats a move at 19200. The beat now comes
    once two thirds have passed (less what the sampler may take before it next looks): fewer beats, and never a gap
    between feeding writes (beat or JOG command) over two thirds of the timeout."""
    sim, d, clock = set_up("dsx7e", 19200, load_ratio=5.0, friction=0.05, noise=0.002, seed=3)
    d.dead_man_waived = False
    log = _record(d)
    tune_inertia(d, TuneRequest(dry_run=True, travel_rev=12.0), clock=clock)  # room for the watchdog's run-on
    p = d.profile
    beat, jog = p.entry("Fn032").address, p.entry("Fn001").address
    timeout_s = sim.bank.effective_value("Pn620") / 1000.0
    feeds = [t for t, op, a, _v in log if op == "W" and a in (beat, jog)]
    gaps = [b - a for a, b in itertools.pairwise(feeds)]
    assert max(gaps) <= 2.0 / 3.0 * timeout_s
    beats = sum(1 for _t, op, a, _v in log if op == "W" and a == beat)
    moves = sum(1 for _t, op, a, v in log if op == "W" and a == jog and v != [0])
    assert beats <= moves / 3
    assert sim.firmware.plant.alarm is None


def test_is620p_moves_end_by_their_own_segment_where_it_stops_inside_the_travel_band(sim_dir):
    """The travel guard cut every IS620P move 10-60 ms before its ramp ended (it allows for a stop command's latency,
    and the plan fills the band): a braking segment (three writes) a move, and shorter moves. A move whose own segment
    stops inside the band (as far past it as the own segments so far ran, twice over) is left to the drive, which
    brakes it there by itself."""
    sim, d, clock = set_up("is620p", 57600, load_ratio=10.0, friction=0.05, noise=0.002, seed=1)
    d.dead_man_waived = False
    log = _record(d)
    said: list[str] = []
    r = tune_inertia(d, TuneRequest(dry_run=True), clock=clock, progress=said.append)
    start = d.profile.entry("H31-00").address
    edges = sum(1 for _t, op, a, v in log if op == "W" and a == start and v == [3])
    moves = sum(1 for m in said if m.startswith("move "))
    braked = edges - moves - 4  # the pilot's two moves stop by command: a start and a braking edge each
    assert moves >= 4 and 0 <= braked <= moves // 2  # before: 6 of 8 moves braked by a segment of their own
    assert r.identified.travel_used_rev <= 2.0 and r.identified.estimate.load_ratio == pytest.approx(10.0, rel=0.03)
    assert sim.firmware.plant.alarm is None
