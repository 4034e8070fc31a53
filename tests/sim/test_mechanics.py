"""Mechanics outside the rigid model (sim.mechanics), measured from the plant's behaviour."""

from __future__ import annotations

import math

import numpy as np
import pytest

from servotool.sim.mechanics import MechanicsSettings
from servotool.sim.plant import TS, DriveGains, MotorData, Plant, PlantSettings

MOTOR = MotorData(
    rated_torque_nm=1.27, rated_speed_rpm=3000, max_speed_rpm=6000, rotor_inertia_kgcm2=0.62, counts_per_rev=131072
)


def plant(load_ratio: float = 4.0, gains: DriveGains | None = None, **mechanics: float) -> Plant:
    return Plant(
        MOTOR,
        PlantSettings(load_ratio=load_ratio, mechanics=MechanicsSettings(**mechanics)),
        gains or DriveGains(inertia_ratio_configured=load_ratio),
    )


def record(p: Plant, seconds: float, what, dt: float = TS) -> np.ndarray:
    out = []
    for _ in range(round(seconds / dt)):
        p.advance_to(p.time + dt)
        out.append(what(p))
    return np.asarray(out)


def dominant_hz(signal: np.ndarray, dt: float, above_hz: float = 4.0) -> float:
    x = np.diff(signal)  # the rate of change: a ramp becomes a constant, an oscillation stays
    freq = np.fft.rfftfreq(x.size, dt)
    spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size))) * (freq > above_hz)
    return float(freq[int(np.argmax(spectrum))])


@pytest.mark.parametrize("hz", [20.0, 80.0])
def test_a_two_mass_load_rings_at_its_configured_resonance(hz):
    p = plant(resonance_hz=hz, resonance_damping=0.01)
    p.set_mode("torque")
    p.set_torque_command(5.0)
    speed = record(p, 1.0, lambda q: q.true_speed_rpm)
    assert dominant_hz(speed, TS) == pytest.approx(hz, rel=0.05)
    # on average the whole load accelerates: J_total, not the motor alone
    accel = (speed[-1] - speed[0]) * 2 * math.pi / 60 / 1.0
    assert accel == pytest.approx(0.05 * 1.27 / (0.62e-4 * 5), rel=0.05)


def test_a_rigid_plant_does_not_ring():
    p = plant()
    p.set_mode("torque")
    p.set_torque_command(50.0)
    speed = record(p, 0.3, lambda q: q.true_speed_rpm)
    trend = np.polyval(np.polyfit(np.arange(speed.size), speed, 1), np.arange(speed.size))
    assert np.max(np.abs(speed - trend)[200:]) < 1.0


def test_backlash_is_lost_motion_the_motor_crosses_alone():
    gap = 0.2
    p = plant(load_ratio=9.0, backlash_rad=gap)
    p.set_mode("torque")
    p.set_torque_command(20.0)
    while p.theta < 0.45 * gap:
        p.advance_to(p.time + TS)
    # the motor crossed (almost) half the gap (it starts centred) alone: the load did not move, and the motor
    # accelerated as its own inertia alone lets it
    assert p.theta - p._defl == 0.0
    assert p.w**2 / (2 * p.theta) == pytest.approx(0.2 * 1.27 / 0.62e-4, rel=0.15)
    record(p, 0.3, lambda q: q.theta)
    assert p._defl == pytest.approx(gap / 2, abs=0.01)  # then it pushes the load on the flank


def test_backlash_shows_as_lost_motion_when_the_motor_reverses():
    gap = 0.1
    p = Plant(
        MOTOR,
        PlantSettings(load_ratio=4.0, coulomb_nm=0.05 * 1.27, mechanics=MechanicsSettings(backlash_rad=gap)),
        DriveGains(inertia_ratio_configured=4.0),
    )
    p.set_mode("speed")
    p.set_speed_command(100.0)
    record(p, 0.5, lambda q: 0.0, dt=0.001)
    p.set_speed_command(-100.0)
    defl = record(p, 0.5, lambda q: q._defl, dt=0.001)
    # forward the motor pushes on one flank against the load's friction, in reverse on the other: it turns
    # through the whole gap while the load stands
    assert defl[0] == pytest.approx(gap / 2, abs=0.005)
    assert defl[-1] == pytest.approx(-gap / 2, abs=0.005)


@pytest.mark.parametrize("position", [0.0, 2.0, 5.0])
def test_arm_gravity_varies_with_position_through_the_gear(position):
    amplitude, gear = 0.3 * 1.27, 10.0
    p = plant(load_ratio=3.0, arm_nm=amplitude, gear=gear, arm_phase_rad=math.radians(30))
    p.theta = position * 2 * math.pi
    p.set_mode("torque")  # no torque, no friction: only the arm acts
    p.advance_to(p.time + 0.002)
    accel = p.w / 0.002
    expected = -amplitude * math.sin(position * 2 * math.pi / gear + math.radians(30)) / (0.62e-4 * 4)
    assert accel == pytest.approx(expected, rel=0.02)


def test_cogging_ripples_at_periods_times_speed():
    p = plant(load_ratio=1.0, cogging_nm=0.05 * 1.27, cogging_periods=6)
    p.set_mode("speed")
    p.set_speed_command(120.0)  # 2 rev/s: 12 ripples per second
    record(p, 0.5, lambda q: 0.0, dt=0.001)
    torque = record(p, 1.0, lambda q: q.true_torque_pct, dt=0.001)
    assert dominant_hz(torque, 0.001) == pytest.approx(12.0, abs=1.0)
    assert 2.0 < np.ptp(torque) < 15.0  # about the +-5 % ripple the loop has to cancel


def test_the_coupling_state_is_carried_over_and_a_stale_state_starts_rigid():
    p = plant(resonance_hz=30.0)
    p.set_mode("torque")
    p.set_torque_command(50.0)
    record(p, 0.05, lambda q: 0.0)
    q = plant(resonance_hz=30.0)
    q.restore(p.state())
    assert (q._defl, q._defl_rate) == (p._defl, p._defl_rate) and p._defl != 0
    r = plant(resonance_hz=30.0)
    r.restore({k: v for k, v in p.state().items() if not k.startswith("_defl")})
    assert r._defl == 0.0 and r.theta == p.theta


def test_a_stiff_coupling_stays_stable_at_the_highest_resonance():
    p = plant(load_ratio=1.0, resonance_hz=500.0, resonance_damping=0.001, backlash_rad=0.01)
    p.set_mode("speed")
    p.set_speed_command(300.0)
    speed = record(p, 0.5, lambda q: q.true_speed_rpm, dt=0.001)
    assert np.all(np.isfinite(speed)) and np.max(np.abs(speed)) < 600
