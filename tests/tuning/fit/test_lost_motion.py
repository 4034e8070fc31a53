"""The lost-motion observer: where the motor may turn without its load behind a gap."""

from __future__ import annotations

import numpy as np

from servotool.tuning.fit.lost_motion import LoadSide, clear_windows, coupled_intervals

T = np.arange(0.0, 0.61, 0.01)
# rad/s: at rest, forward at 300 rad/s^2 for 0.2 s, braking as hard, at rest
W = np.interp(T, [0.0, 0.1, 0.3, 0.5, 0.6], [0.0, 0.0, 60.0, 0.0, 0.0])


def _marks(coupled: np.ndarray) -> str:
    return "".join("C" if c else "." for c in coupled)


def test_the_motor_crosses_the_gap_alone_where_the_braking_torque_reverses_the_flank():
    load = LoadSide(inertia=2e-4, coulomb=0.01, viscous=0.0, load_torque=0.0)
    coupled = coupled_intervals(T, W, load, gap=0.1)
    marks = _marks(coupled)
    # the first motion closes the half gap the load is assumed to rest in, the acceleration pushes it along, and
    # where braking needs the flank to pull (0.06 N*m against 0.01 of friction) the motor runs ahead alone
    assert marks.index("C") in (11, 12)
    assert coupled[13:29].all()
    loose = [i for i in range(29, 40) if not coupled[i]]
    assert loose and loose[0] in (29, 30) and len(loose) <= 5
    assert coupled[loose[-1] + 1 :].all()


def test_friction_that_brakes_the_load_harder_than_the_ramp_keeps_it_on_its_flank():
    load = LoadSide(inertia=2e-4, coulomb=0.1, viscous=0.0, load_torque=0.0)
    coupled = coupled_intervals(T, W, load, gap=0.1)
    assert coupled[13:].all(), _marks(coupled)


def test_a_load_with_no_inertia_of_its_own_is_always_coupled():
    load = LoadSide(inertia=0.0, coulomb=0.01, viscous=0.0, load_torque=0.0)
    assert coupled_intervals(T, W, load).all()


def test_windows_near_a_loose_interval_are_not_clear():
    coupled = np.array([True] * 5 + [False] + [True] * 5)  # interval 5 (samples 5 to 6) loose
    starts = np.arange(11)
    ends = starts + 1

    def cleared(margin: int) -> list[int]:
        return np.flatnonzero(~clear_windows(starts, ends, coupled, margin)).tolist()

    assert cleared(0) == [5]
    assert cleared(1) == [4, 5, 6]
    assert cleared(2) == [3, 4, 5, 6, 7]
