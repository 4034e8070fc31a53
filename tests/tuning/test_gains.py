"""Gain suggestions: the rigidity table, the cascade rules, scaling with inertia and refusal of bad input."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest

from servotool.tuning.gains import (
    RIGIDITY_BANDWIDTH_HZ,
    GainSuggestion,
    rigidity_bandwidth_hz,
    suggest_gains,
)

ROTOR_KGCM2 = 0.29
JM = ROTOR_KGCM2 * 1e-4


def by_rigidity(rigidity: int, ratio: float = 3.0) -> GainSuggestion:
    return suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, load_ratio=ratio, rigidity=rigidity)


def test_rigidity_table_spans_1_to_400_hz_geometrically() -> None:
    assert len(RIGIDITY_BANDWIDTH_HZ) == 31
    assert RIGIDITY_BANDWIDTH_HZ[0] == 1.0 and RIGIDITY_BANDWIDTH_HZ[-1] == 400.0
    steps = [b / a for a, b in pairwise(RIGIDITY_BANDWIDTH_HZ)]
    assert all(1.15 < s < 1.30 for s in steps)  # 400**(1/30) = 1.221, blurred only by 0.1 Hz rounding
    assert rigidity_bandwidth_hz(16) == pytest.approx(20.0)


def test_gains_are_monotonic_in_rigidity() -> None:
    gains = [by_rigidity(r) for r in range(1, 32)]
    for lo, hi in pairwise(gains):
        assert hi.bandwidth_hz > lo.bandwidth_hz
        assert hi.speed_loop_gain_hz > lo.speed_loop_gain_hz
        assert hi.speed_kp_nm_s_per_rad > lo.speed_kp_nm_s_per_rad
        assert hi.position_loop_gain_per_s > lo.position_loop_gain_per_s
        assert hi.speed_integral_ms < lo.speed_integral_ms
        assert hi.torque_filter_ms < lo.torque_filter_ms
    assert all(g.rigidity == r for r, g in enumerate(gains, start=1))


def test_rules_at_an_explicit_bandwidth() -> None:
    g = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, load_ratio=3.0, bandwidth_hz=50.0)
    wc = 2 * math.pi * 50.0
    assert g.rigidity is None
    assert g.speed_loop_gain_hz == 50.0
    assert g.speed_kp_nm_s_per_rad == pytest.approx(wc * 4 * JM)
    assert g.speed_integral_ms == pytest.approx(4000 / wc)  # 12.7 ms
    assert g.position_loop_gain_per_s == pytest.approx(wc / 4)  # 78.5 1/s
    assert g.torque_filter_ms == pytest.approx(1000 / (4 * wc))  # 0.80 ms


def test_absolute_gain_scales_with_inertia_and_hz_gains_do_not() -> None:
    bare = by_rigidity(14, ratio=0.0)
    heavy = by_rigidity(14, ratio=9.0)
    assert heavy.speed_kp_nm_s_per_rad == pytest.approx(10 * bare.speed_kp_nm_s_per_rad)
    assert heavy.j_total_kgm2 == pytest.approx(10 * JM)
    assert heavy.speed_loop_gain_hz == bare.speed_loop_gain_hz
    assert heavy.speed_integral_ms == bare.speed_integral_ms


def test_total_inertia_and_ratio_inputs_agree() -> None:
    from_ratio = by_rigidity(12, ratio=20.0)
    from_j = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, j_total_kgm2=21 * JM, rigidity=12)
    assert from_j.load_ratio == pytest.approx(20.0)
    assert from_j.speed_kp_nm_s_per_rad == pytest.approx(from_ratio.speed_kp_nm_s_per_rad)


def test_identified_inertia_a_hair_below_the_rotor_is_taken_as_the_rotor() -> None:
    g = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, j_total_kgm2=0.99 * JM, rigidity=10)
    assert g.load_ratio == 0.0 and g.j_total_kgm2 == pytest.approx(JM)


@pytest.mark.parametrize("rigidity", [0, 32, -1, 3.5, True, "10"])
def test_rejects_bad_rigidity(rigidity: object) -> None:
    with pytest.raises(ValueError, match="rigidity"):
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, load_ratio=1.0, rigidity=rigidity)  # type: ignore[arg-type]


@pytest.mark.parametrize("bandwidth", [0.0, -5.0, math.inf, math.nan, 5000.0])
def test_rejects_bad_bandwidth(bandwidth: float) -> None:
    with pytest.raises(ValueError, match="bandwidth"):
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, load_ratio=1.0, bandwidth_hz=bandwidth)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"load_ratio": 1.0}, "exactly one of rigidity"),
        ({"load_ratio": 1.0, "rigidity": 5, "bandwidth_hz": 10.0}, "exactly one of rigidity"),
        ({"rigidity": 5}, "exactly one of load_ratio"),
        ({"load_ratio": 1.0, "j_total_kgm2": 1e-4, "rigidity": 5}, "exactly one of load_ratio"),
        ({"load_ratio": -0.5, "rigidity": 5}, "load ratio"),
        ({"load_ratio": math.nan, "rigidity": 5}, "load ratio"),
        ({"j_total_kgm2": 0.0, "rigidity": 5}, "total inertia"),
        ({"j_total_kgm2": 0.5 * JM, "rigidity": 5}, "below the rotor inertia"),
    ],
)
def test_rejects_bad_inertia_and_missing_choices(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("rotor", [0.0, -0.3, math.nan])
def test_rejects_bad_rotor_inertia(rotor: float) -> None:
    with pytest.raises(ValueError, match="rotor inertia"):
        suggest_gains(rotor_inertia_kgcm2=rotor, load_ratio=1.0, rigidity=5)


def test_gain_units_follow_what_each_drive_prints():
    from servotool.model.gain_units import from_canonical, to_canonical
    from servotool.model.loader import load_profile

    sdc, dsx = load_profile("sdc"), load_profile("dsx7e")
    cutoff = sdc.role("torque_filter")                   # PN50: a cutoff in Hz, smaller = slower
    assert to_canonical("torque_filter", cutoff, 100.0) == pytest.approx(1.59, abs=0.01)
    assert from_canonical("torque_filter", cutoff, to_canonical("torque_filter", cutoff, 100.0)) == pytest.approx(100)
    assert to_canonical("position_loop_gain", sdc.role("position_loop_gain"), 300.0) == 30.0   # no unit: 0.1/s
    assert to_canonical("position_loop_gain", dsx.role("position_loop_gain"), 32.0) == 32.0    # printed 1/s
    assert to_canonical("torque_filter", dsx.role("torque_filter"), 0.5) == 0.5
