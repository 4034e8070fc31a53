"""Physics of the simulated plant, measured from its behaviour."""

from __future__ import annotations

import math

import pytest

from servotool.sim.plant import RAD_S_PER_RPM, DriveGains, MotorData, Plant, PlantSettings

MOTOR = MotorData(
    rated_torque_nm=1.27, rated_speed_rpm=3000, max_speed_rpm=6000, rotor_inertia_kgcm2=0.62, counts_per_rev=131072
)


def plant(**settings) -> Plant:
    gains = settings.pop("gains", DriveGains())
    return Plant(MOTOR, PlantSettings(**settings), gains)


def run(p: Plant, seconds: float, dt: float = 0.001) -> list[float]:
    out = []
    end = p.time + seconds
    while p.time < end - 1e-12:
        p.advance_to(min(end, p.time + dt))
        out.append(p.true_speed_rpm)
    return out


def test_constant_torque_gives_the_right_acceleration():
    p = plant(load_ratio=3.0)
    p.set_mode("torque")
    p.set_torque_command(50.0)
    run(p, 0.01)  # let the torque filter and current loop settle
    w0, t0 = p.true_speed_rpm, p.time
    run(p, 0.1)
    accel = (p.true_speed_rpm - w0) * RAD_S_PER_RPM / (p.time - t0)
    expected = 0.5 * 1.27 / (0.62e-4 * 4)
    assert accel == pytest.approx(expected, rel=0.01)


def test_coulomb_friction_coasts_down_in_the_expected_time_and_stays_stopped():
    p = plant(load_ratio=1.0, coulomb_nm=0.05)
    p.w = 1000 * RAD_S_PER_RPM
    speeds = run(p, 1.0)
    j = 0.62e-4 * 2
    t_stop = 1000 * RAD_S_PER_RPM * j / 0.05
    stopped_at = next(i for i, v in enumerate(speeds) if v == 0.0) * 0.001
    assert stopped_at == pytest.approx(t_stop, abs=0.002)
    assert all(v == 0.0 for v in speeds[int(t_stop * 1000) + 3 :])


def test_gravity_pulls_when_off_and_is_held_by_the_speed_loop():
    p = plant(load_ratio=2.0, coulomb_nm=0.01, load_torque_nm=0.3)
    run(p, 0.05)
    assert p.true_speed_rpm < -10  # servo off: the load falls back
    p = plant(load_ratio=2.0, coulomb_nm=0.01, load_torque_nm=0.3)
    p.set_mode("speed")
    p.set_speed_command(0)
    run(p, 0.5)
    assert abs(p.true_speed_rpm) < 1.0
    assert p.true_torque_pct == pytest.approx(0.3 / 1.27 * 100, abs=1.5)


def ripple(true_ratio: float, configured: float, hz: float = 80.0) -> tuple[float, float]:
    p = plant(
        load_ratio=true_ratio,
        coulomb_nm=0.02,
        gains=DriveGains(
            inertia_ratio_configured=configured,
            speed_gain_hz=hz,
            speed_integral_ms=20,
            torque_filter_ms=0.5,
            jog_accel_ms=200,
        ),
    )
    p.set_mode("speed")
    p.set_speed_command(300)
    speeds = run(p, 1.0, dt=0.00025)
    tail = speeds[len(speeds) // 2 :]
    return max(speeds) - 300, max(tail) - min(tail)


def test_matched_inertia_settles_and_ten_times_too_high_oscillates():
    overshoot, tail = ripple(5.0, 5.0)
    assert overshoot < 30 and tail < 1.0  # a PI step overshoot that dies out
    _, tail_bad = ripple(5.0, 50.0)
    assert tail_bad > 30, "a 10x too high inertia ratio must make the speed loop oscillate"


def test_too_low_inertia_ratio_is_sluggish_and_overshoots():
    overshoot_ok, _ = ripple(5.0, 5.0, hz=40)
    overshoot_low, _ = ripple(5.0, 0.5, hz=40)
    assert overshoot_low > overshoot_ok + 10


def test_overspeed_latches_stops_and_clears_only_when_gone():
    p = plant(load_ratio=0.0, gains=DriveGains(max_speed_rpm=1000))
    p.set_mode("torque")
    p.set_torque_command(100)
    run(p, 0.2)
    assert p.alarm == "overspeed"
    run(p, 0.5)
    assert not p.servo_on and abs(p.true_speed_rpm) < 1
    assert p.clear_alarms() and p.alarm is None


def test_overload_latches_and_needs_cooling():
    p = plant(load_ratio=0.0, load_torque_nm=3.5)  # a load the motor can hold only at ~280 % torque
    p.set_mode("speed")
    p.set_speed_command(0)
    run(p, 2.0)
    assert p.alarm == "overload"
    assert not p.clear_alarms()


def tripped_then_unloaded() -> Plant:
    """An overload trip, with the load taken off at that moment so the stopped axis rests (this plant has no brake)."""
    p = plant(load_ratio=0.0, load_torque_nm=3.5)
    p.set_mode("speed")
    p.set_speed_command(0)
    while p.alarm is None:
        run(p, 0.01)
    p.set_settings(PlantSettings(load_ratio=0.0, coulomb_nm=0.5))
    run(p, 0.5)
    assert p.alarm == "overload" and p.w == 0.0 and not p.clear_alarms()
    return p


def test_overload_clears_after_cooling():
    p = tripped_then_unloaded()
    run(p, 6.0)  # no current: about 1 unit of I^2t per second
    assert p.clear_alarms() and p.alarm is None


def test_an_idle_gap_cools_the_motor_too():
    p = tripped_then_unloaded()
    for _ in range(12):  # requests every 10 s: each gap is skipped as 'at rest'
        p.advance_to(p.time + 10.0)
    assert p.clear_alarms()


def test_same_seed_same_readouts():
    def readings(seed: int) -> list[float]:
        p = plant(load_ratio=1.0, noise=0.01, seed=seed)
        p.set_mode("speed")
        p.set_speed_command(100)
        out = []
        for _ in range(20):
            run(p, 0.01)
            out.append(p.speed_rpm)
        return out

    assert readings(7) == readings(7)
    assert readings(7) != readings(8)


def test_idle_gap_is_cheap():
    import time

    p = plant()
    t0 = time.process_time()
    p.advance_to(3600.0)
    assert time.process_time() - t0 < 0.5 and p.time == 3600.0
    assert math.isclose(p.true_speed_rpm, 0.0)


def test_position_mode_moves_under_speed_control_then_holds_where_the_profile_stopped():
    p = plant(
        load_ratio=2.0,
        coulomb_nm=0.01,
        load_torque_nm=0.5,
        gains=DriveGains(inertia_ratio_configured=2.0, speed_gain_hz=40),
    )
    p.set_mode("position")
    p.set_speed_command(300)
    run(p, 0.5)
    assert p.true_speed_rpm == pytest.approx(300, abs=5) and p.following_error_counts == 0
    p.set_speed_command(0)
    run(p, 0.3)
    stopped = p.position_rev
    run(p, 1.0)
    assert abs(p.position_rev - stopped) < 0.01 and abs(p.following_error_counts) < 0.001 * MOTOR.counts_per_rev
    assert p.true_torque_pct == pytest.approx(0.5 / 1.27 * 100, abs=2)  # holding the gravity load


def test_a_closed_brake_holds_and_an_alarm_stop_ends_in_it():
    p = plant(
        load_ratio=2.0,
        load_torque_nm=2.5,
        brake_nm=3.0,  # twice the rated torque: more than the drive
        gains=DriveGains(torque_limit_pct=150),
    )
    run(p, 1.0)
    assert p.w == 0.0 and p.theta == 0.0  # servo off: the brake holds
    p.set_mode("position")
    run(p, 2.0)
    assert p.alarm == "following_error" and not p.servo_on and p.brake_closed
    at_rest = p.theta
    run(p, 1.0)
    assert p.w == 0.0 and p.theta == at_rest


def test_a_restored_state_continues_the_same_motion():
    p = plant(load_ratio=2.0, coulomb_nm=0.02)
    p.set_mode("position")
    p.set_speed_command(500)
    run(p, 0.1)
    q = plant(load_ratio=2.0, coulomb_nm=0.02)
    q.restore(p.state(), shift=10.0)
    assert q.time == p.time + 10.0 and q.mode == "position"
    run(p, 0.2)
    run(q, 0.2)
    assert q.theta == pytest.approx(p.theta) and q.true_speed_rpm == pytest.approx(p.true_speed_rpm)
