"""Gain suggestions: each drive's own levels, the factory ratios, margins, scaling with inertia, bad input."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest

from servotool.model.loader import load_profile
from servotool.tuning.control.gains import LEVEL_STEP, GainSuggestion, rigidity_scale, suggest_gains
from servotool.tuning.control.margins import margins

ROTOR_KGCM2 = 0.29
JM = ROTOR_KGCM2 * 1e-4
SD25 = rigidity_scale(load_profile("sd25"))


def by_rigidity(rigidity: int, ratio: float = 3.0, scale=SD25) -> GainSuggestion:
    return suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=scale, load_ratio=ratio, rigidity=rigidity)


@pytest.mark.parametrize(
    "profile_id, levels, factory_level, factory_hz, parameter",
    [
        ("sd25", (1, 40), 6, 60.0, "Po010"),
        ("is620p", (0, 31), 12, 25.0, "H09-01"),
        ("dsx7e", (0, 31), 13, 18.0, "Pn003"),
        ("sdc", (0, 19), 10, 200.0, None),
    ],
)
def test_each_drive_has_its_own_levels_anchored_at_its_factory_gains(
    profile_id, levels, factory_level, factory_hz, parameter
) -> None:
    """The drive's own factory level gives its factory speed gain (SD25: 60 Hz, not servotool's old 2.7 Hz)."""
    scale = rigidity_scale(load_profile(profile_id))
    assert (scale.lowest, scale.highest, scale.factory_level) == (*levels, factory_level)
    assert scale.bandwidth_hz(factory_level) == pytest.approx(factory_hz)
    assert scale.bandwidth_hz(factory_level + 4) == pytest.approx(2 * factory_hz)  # four levels per doubling
    assert (scale.parameter.code if scale.parameter else None) == parameter


def test_gains_are_monotonic_in_rigidity() -> None:
    gains = [by_rigidity(r) for r in range(1, 41)]
    for lo, hi in pairwise(gains):
        assert hi.bandwidth_hz == pytest.approx(lo.bandwidth_hz * LEVEL_STEP)
        assert hi.speed_kp_nm_s_per_rad > lo.speed_kp_nm_s_per_rad
        assert hi.position_loop_gain_per_s > lo.position_loop_gain_per_s
        assert hi.speed_integral_ms < lo.speed_integral_ms
        assert hi.torque_filter_ms < lo.torque_filter_ms
    assert all(g.rigidity == r for r, g in enumerate(gains, start=1))


def test_the_factory_ratios_hold_at_every_level_and_the_filter_sits_8x_above_or_more() -> None:
    is620p = rigidity_scale(load_profile("is620p"))
    for level in (0, 12, 20, 31):
        g = by_rigidity(level, scale=is620p)
        wc = 2 * math.pi * g.speed_loop_gain_hz
        assert wc * g.speed_integral_ms / 1000 == pytest.approx(2 * math.pi * 25 * 0.03183)  # the PI zero's place
        assert g.position_loop_gain_per_s / g.speed_loop_gain_hz == pytest.approx(40 / 25)
        assert 1000 / (2 * math.pi * g.torque_filter_ms) >= 7.9 * g.speed_loop_gain_hz  # not the old 4x


def test_rules_at_an_explicit_bandwidth() -> None:
    g = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, load_ratio=3.0, bandwidth_hz=120.0)
    assert g.rigidity is None and g.speed_loop_gain_hz == 120.0
    assert g.speed_kp_nm_s_per_rad == pytest.approx(2 * math.pi * 120 * 4 * JM)
    assert g.speed_integral_ms == pytest.approx(25.0)  # the factory 50 ms at 60 Hz, scaled
    assert g.position_loop_gain_per_s == pytest.approx(80.0)


def test_absolute_gain_scales_with_inertia_and_hz_gains_do_not() -> None:
    bare = by_rigidity(14, ratio=0.0)
    heavy = by_rigidity(14, ratio=9.0)
    assert heavy.speed_kp_nm_s_per_rad == pytest.approx(10 * bare.speed_kp_nm_s_per_rad)
    assert heavy.j_total_kgm2 == pytest.approx(10 * JM)
    assert heavy.speed_loop_gain_hz == bare.speed_loop_gain_hz
    assert heavy.speed_integral_ms == bare.speed_integral_ms


def test_margins_fall_with_the_level_and_match_a_textbook_loop() -> None:
    is620p = rigidity_scale(load_profile("is620p"))
    found = [margins(is620p.factory.scaled(is620p.factor(level)), 4 * JM) for level in (12, 21, 30)]
    assert 60 < found[0].phase_deg < 75 and found[0].gain_db > 15  # the factory level: comfortable
    assert 40 < found[1].phase_deg < 50  # about the 45 degree limit
    assert found[2].phase_deg < 0 and not found[2].ok()  # unstable
    # IS620P's factory gains configured for ratio 1 on a load of 49: the speed loop alone is stable but poorly
    # damped, a position loop around it is unstable (the growing oscillation of a position hold, issue 16)
    far_off = margins(is620p.factory, 50 * JM, 2 * JM)
    assert 0 < far_off.speed_phase_deg < 30 and far_off.position_phase_deg < 0


def test_total_inertia_and_ratio_inputs_agree() -> None:
    from_ratio = by_rigidity(12, ratio=20.0)
    from_j = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, j_total_kgm2=21 * JM, rigidity=12)
    assert from_j.load_ratio == pytest.approx(20.0)
    assert from_j.speed_kp_nm_s_per_rad == pytest.approx(from_ratio.speed_kp_nm_s_per_rad)


def test_identified_inertia_a_hair_below_the_rotor_is_taken_as_the_rotor() -> None:
    g = suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, j_total_kgm2=0.99 * JM, rigidity=10)
    assert g.load_ratio == 0.0 and g.j_total_kgm2 == pytest.approx(JM)


@pytest.mark.parametrize("rigidity", [0, 41, -1, 3.5, True, "10"])
def test_rejects_bad_rigidity(rigidity: object) -> None:
    with pytest.raises(ValueError, match=r"rigidity must be 1\.\.40"):
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, load_ratio=1.0, rigidity=rigidity)  # type: ignore[arg-type]


@pytest.mark.parametrize("bandwidth", [0.0, -5.0, math.inf, math.nan, 5000.0])
def test_rejects_bad_bandwidth(bandwidth: float) -> None:
    with pytest.raises(ValueError, match="bandwidth"):
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, load_ratio=1.0, bandwidth_hz=bandwidth)


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
        suggest_gains(rotor_inertia_kgcm2=ROTOR_KGCM2, scale=SD25, **kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize("rotor", [0.0, -0.3, math.nan])
def test_rejects_bad_rotor_inertia(rotor: float) -> None:
    with pytest.raises(ValueError, match="rotor inertia"):
        suggest_gains(rotor_inertia_kgcm2=rotor, scale=SD25, load_ratio=1.0, rigidity=5)


def test_gain_units_follow_what_each_drive_prints():
    from servotool.model.gain_units import from_canonical, to_canonical
    from servotool.model.loader import load_profile

    sdc, dsx = load_profile("sdc"), load_profile("dsx7e")
    cutoff = sdc.role("torque_filter")  # PN50: a cutoff in Hz, smaller = slower
    assert to_canonical("torque_filter", cutoff, 100.0) == pytest.approx(1.59, abs=0.01)
    assert from_canonical("torque_filter", cutoff, to_canonical("torque_filter", cutoff, 100.0)) == pytest.approx(100)
    assert to_canonical("position_loop_gain", sdc.role("position_loop_gain"), 300.0) == 30.0  # no unit: 0.1/s
    assert to_canonical("position_loop_gain", dsx.role("position_loop_gain"), 32.0) == 32.0  # printed 1/s
    assert to_canonical("torque_filter", dsx.role("torque_filter"), 0.5) == 0.5
