"""The resonance check's model of a load behind a spring (tuning.fit.resonance)."""

from __future__ import annotations

import numpy as np

from servotool.tuning.fit.resonance import follower_speed


def test_a_load_behind_a_spring_rings_at_its_own_resonance_when_the_motor_starts_to_accelerate():
    """Motor speed a*t from rest: the load's speed through a spring and damper is a*t - (a/wd) e^(-zeta w t)
    sin(wd t) (its own resonance w, damped at wd), exactly at the samples however unevenly they come."""
    rng = np.random.default_rng(3)
    t = np.concatenate(([0.0], np.cumsum(rng.uniform(0.001, 0.02, 400))))
    a = 50.0
    hz, zeta = np.array([12.0, 30.0, 5.0]), np.array([0.05, 0.2, 0.9])
    load = follower_speed(t, a * t, hz, zeta)
    w = 2 * np.pi * hz
    wd = w * np.sqrt(1 - zeta**2)
    expected = a * t[:, None] - a / wd * np.exp(-zeta * w * t[:, None]) * np.sin(wd * t[:, None])
    assert load.shape == (t.size, 3)
    assert np.max(np.abs(load - expected)) < 1e-3 * a / wd.min()
