"""Finding a drive's profile from its answers (ops.scan.find, ops.identity.choose): one profile fits, or the
candidates are listed; against `sim serve` on RTU over TCP."""

from __future__ import annotations

import pytest

from servotool.connection import ConnectOptions
from servotool.errors import DeviceError, ProfileNotFound
from servotool.model.loader import builtin_dir, load_profile
from servotool.ops.identity import choose, shipped_profiles
from servotool.ops.scan import find


def test_one_fitting_profile_is_chosen(sim_serve):
    port = sim_serve("-P", "is620p")
    found = find(ConnectOptions(port=port), 1, shipped_profiles())
    assert found.line is None  # RTU over TCP: no line settings to find
    assert choose(list(found.ranked), port).profile.id == "is620p"


def test_two_profiles_that_both_fit_are_both_named(sim_serve, tmp_path):
    """A second profile with SD25's identity checks (a rebadged drive, a user's own copy): which one describes the
    drive cannot be told from its answers, so neither is taken."""
    twin = tmp_path / "sd25-rebadged.yaml"
    twin.write_text(
        (builtin_dir() / "sd25.yaml").read_text(encoding="utf-8").replace("id: sd25\n", "id: sd25-rebadged\n", 1)
    )
    port = sim_serve("-P", "sd25")
    found = find(ConnectOptions(port=port), 1, [*shipped_profiles(), load_profile(twin)])
    with pytest.raises(ProfileNotFound) as caught:
        choose(list(found.ranked), port)
    assert caught.value.fits and [pid for pid, _ in caught.value.candidates] == ["sd25", "sd25-rebadged"]
    assert "So-00 (address 800) reads 100" in str(caught.value) and "choose one with --profile" in str(caught.value)


def test_a_unit_that_does_not_answer_is_a_device_error(sim_serve):
    port = sim_serve("-P", "sdc")
    with pytest.raises(DeviceError, match="no answer from unit 7"):
        find(ConnectOptions(port=port), 7, shipped_profiles())
