"""Trace capture: the trigger logic on synthetic samples (rising, falling, bit, pre-trigger share, repeat), the
expressions, the CSV round trip, and a capture from the simulated drive on virtual time during a JOG."""

from __future__ import annotations

import pytest

from servotool.clock import VirtualClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.loader import load_profile
from servotool.motion.stop import stop_sequence
from servotool.ops.trace import Sampler, Tracer, TraceSample, TriggerBuffer, Window, parse_trigger
from servotool.ops.trace_file import read_table, write_trace
from servotool.sim.firmware import build_drive
from servotool.sim.virtual import VirtualLink

P = load_profile("dsx7e")
SPEED, STATUS = P.role("speed_feedback"), P.role("servo_status")


def _samples(values: list[float], code: str = SPEED.code, dt: float = 0.01) -> list[TraceSample]:
    return [TraceSample(i * dt, {code: float(v)}) for i, v in enumerate(values)]


def _feed(buf: TriggerBuffer, samples: list[TraceSample]):
    return [c for s in samples if (c := buf.feed(s)) is not None]


def test_rising_trigger_keeps_the_pre_trigger_share_from_the_ring_buffer():
    trig = parse_trigger(P, f"{SPEED.code}>100")
    values = [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 150, 160, 170, 180, 190, 200, 210, 220, 230, 240]
    (cap,) = _feed(TriggerBuffer(trig, Window(samples=10, pre_share=0.3), [SPEED.code]), _samples(values))
    assert cap.pre_samples == 3
    assert cap.values[SPEED.code] == [70, 80, 90, 150, 160, 170, 180, 190, 200, 210]
    assert cap.t[3] == 0.0 and cap.t[0] == pytest.approx(-0.03)
    assert cap.trigger_t == pytest.approx(0.10)


def test_falling_trigger_ignores_rising_crossings_and_a_level_already_below():
    trig = parse_trigger(P, f"{SPEED.code}<-5")
    values = [-10, -20, 0, 10, -3, -8, -9, -10]  # starts below: no edge; first fall through -5 is at index 5
    (cap,) = _feed(TriggerBuffer(trig, Window(samples=3, pre_share=0), [SPEED.code]), _samples(values))
    assert cap.values[SPEED.code] == [-8, -9, -10]


def test_bit_triggers_by_name_and_number_on_set_and_clear():
    moving = next(b for b, n in STATUS.bits.items() if n == "moving")
    words = [0, 1, 1 | 1 << moving, 1 | 1 << moving, 1, 1, 1]
    for expr, first in ((f"{STATUS.code}.moving", 2), (f"{STATUS.code}.{moving}", 2), (f"{STATUS.code}.moving=0", 4)):
        trig = parse_trigger(P, expr)
        (cap,) = _feed(TriggerBuffer(trig, Window(samples=2, pre_share=0), [STATUS.code]), _samples(words, STATUS.code))
        assert cap.trigger_t == pytest.approx(first * 0.01), expr


def test_repeat_needs_a_new_edge_and_a_duration_window_keeps_its_pre_time():
    trig = parse_trigger(P, f"{SPEED.code}>50")
    wave = ([0] * 5 + [100] * 10) * 3  # three rising edges, 0.15 s apart
    caps = _feed(TriggerBuffer(trig, Window(duration_s=0.1, pre_share=0.2), [SPEED.code]), _samples(wave))
    assert len(caps) == 3
    for cap in caps:
        assert cap.t[0] == pytest.approx(-0.02)  # 20 % of 0.1 s before the trigger
        assert cap.t[-1] >= 0.08 - 1e-9
        assert cap.values[SPEED.code][cap.pre_samples] == 100
    assert [c.index for c in caps] == [1, 2, 3]


def test_without_a_trigger_the_capture_starts_at_once():
    (cap, cap2) = _feed(TriggerBuffer(None, Window(samples=4, pre_share=0.5), [SPEED.code]), _samples(range(8)))
    assert cap.values[SPEED.code] == [0, 1, 2, 3] and cap.pre_samples == 0
    assert cap2.values[SPEED.code] == [4, 5, 6, 7]


@pytest.mark.parametrize(
    "expr, message",
    [
        ("Un000=5", "use CODE>LEVEL"),
        ("Un000>fast", "not a level"),
        (f"{STATUS.code}.nosuch", "no bit"),
        (f"{STATUS.code}.99", "bits 0..15"),
        ("Pn999>1", "Pn999"),
    ],
)
def test_bad_trigger_expressions_say_what_is_wrong(expr, message):
    with pytest.raises(UsageError, match=message):
        parse_trigger(P, expr)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({}, "--samples N or --duration"),
        ({"samples": 1}, "at least 2"),
        ({"duration_s": -1}, "> 0"),
        ({"samples": 10, "pre_share": 1.0}, "0..99"),
    ],
)
def test_bad_windows_are_refused(kwargs, message):
    with pytest.raises(UsageError, match=message):
        Window(**kwargs)


def _virtual():
    clock = VirtualClock(10.0)
    sim = build_drive(P, 1, clock, persist=False)
    return Drive(VirtualLink([sim], clock), P, 1), clock


def test_a_trace_of_a_jog_on_the_simulator_catches_the_start_with_its_rate(sim_dir, tmp_path):
    from servotool.motion.jogger import Jogger

    d, clock = _virtual()
    torque = P.role("torque_feedback")
    jogger = Jogger(d, clock=clock)
    plan = jogger.plan(300, 0.6)
    started = {"n": 0}

    def start_jog_after_a_while() -> bool:  # the JOG starts while the trace is armed
        started["n"] += 1
        if started["n"] == 50:
            jogger.set_speed(plan.speed_rpm)
            jogger.command(1)
        if started["n"] % 20 == 0:
            jogger.beat()
        return False

    tracer = Tracer(
        d,
        [SPEED, torque],
        parse_trigger(P, f"{SPEED.code}>150"),
        Window(samples=200, pre_share=0.25),
        clock=clock,
        stop=start_jog_after_a_while,
        timeout_s=5,
    )
    (cap,) = list(tracer.run())
    assert stop_sequence(d, jogger, {}, wait_s=1.0, clock=clock).confirmed
    speed = cap.values[SPEED.code]
    assert cap.pre_samples == 50 and len(speed) == 200
    assert speed[49] < 150 <= speed[50]  # the trigger sample at t = 0
    assert max(speed) > 250 and cap.values[torque.code][0] == pytest.approx(0, abs=5)
    assert tracer.sampler.requests_per_sample == 1  # speed and torque in one coalesced read
    tm = cap.timing
    assert tm.rate_hz > 200 and tm.jitter_ms is not None  # 115200 baud: one read is ~2 ms of wire time
    out = tmp_path / "jog.csv"
    write_trace(out, [cap], tracer.entries, ["servotool trace: test"])
    table = read_table(out)
    assert [s.label for s in table.series] == [f"{SPEED.code} [rpm]", f"{torque.code} [{torque.unit}]"]
    assert table.series[0].values == pytest.approx(speed) and table.t[50] == 0.0
    assert table.about[0] == "servotool trace: test" and table.capture == [1] * 200
    with pytest.raises(UsageError, match="exists"):
        write_trace(out, [cap], tracer.entries, [])


def test_a_trigger_that_never_fires_times_out_with_the_range_seen(sim_dir):
    d, clock = _virtual()
    tracer = Tracer(d, [SPEED], parse_trigger(P, f"{SPEED.code}>100"), Window(samples=10), clock=clock, timeout_s=0.5)
    assert list(tracer.run()) == []
    assert tracer.timed_out and tracer.buffer.high < 100


def test_the_sampler_records_what_a_motion_loop_leaves_it(sim_dir):
    d, clock = _virtual()
    sampler = Sampler(d, [SPEED], clock)
    sampler.sample_for(0.05)
    sampler.sample_for(0.05)
    rec = sampler.recording()
    assert rec.t[-1] >= 0.09 and len(rec.t) > 20
