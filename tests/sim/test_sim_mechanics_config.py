"""sim config's mechanics outside the rigid model: set, shown, persisted with the drive; bad values refused."""

from __future__ import annotations

MECHANICS = {
    "--resonance-hz": ("resonance_hz", 25.0),
    "--resonance-damping": ("resonance_damping", 0.1),
    "--backlash-rad": ("backlash_rad", 0.15),
    "--arm-gravity": ("arm_gravity", 0.3),
    "--arm-angle": ("arm_angle", 45.0),
    "--gear": ("gear", 8.0),
    "--cogging": ("cogging", 0.03),
    "--cogging-periods": ("cogging_periods", 12),
}


def test_sim_config_sets_every_mechanics_option_and_sim_show_lists_them(cli):
    default = cli("sim", "show", "--json").json()["settings"]
    assert [default[k] for k in ("resonance_hz", "backlash_rad", "arm_gravity", "cogging")] == [0, 0, 0, 0]
    args = [a for opt, (_name, value) in MECHANICS.items() for a in (opt, f"{value:g}")]
    assert cli("sim", "config", "--load-ratio", "4", *args).code == 0
    shown = cli("sim", "show", "--json").json()["settings"]
    assert {name: shown[name] for name, _v in MECHANICS.values()} == dict(MECHANICS.values())
    text = cli("sim", "show").out
    assert all(name in text for name, _v in MECHANICS.values())


BAD = [
    (("--resonance-hz", "900"), "resonance_hz"),
    (("--backlash-rad", "-0.1"), "backlash_rad"),
    (("--cogging-periods", "0"), "cogging_periods"),
    (("--load-ratio", "0", "--resonance-hz", "20"), "load_ratio > 0"),
]


def test_a_bad_mechanics_value_is_refused_in_one_line_and_nothing_changes(cli):
    before = cli("sim", "show", "--json").json()["settings"]
    for args, words in BAD:
        r = cli("sim", "config", *args)
        assert r.code == 2 and words in r.err and len(r.err.strip().splitlines()) == 1, r.err
    assert cli("sim", "show", "--json").json()["settings"] == before
