"""Compiled profiles: a parsed profile is kept in the cache folder keyed by the file's content and reused."""

from __future__ import annotations

import shutil

import pytest

from servotool.model import loader


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVOTOOL_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache" / "profiles"


@pytest.fixture
def copy(tmp_path):
    """A copy of the dsx7e profile that the tests may edit."""
    path = tmp_path / "dsx7e.yaml"
    shutil.copy(loader.builtin_dir() / "dsx7e.yaml", path)
    return path


def _no_parsing(monkeypatch):
    def refuse(*_args, **_kwargs):
        raise AssertionError("parsed the YAML although the compiled profile was cached")

    monkeypatch.setattr(loader, "parse_yaml", refuse)


def test_second_read_comes_from_the_compiled_cache(cache, copy, monkeypatch):
    first, problems = loader.read_profile(copy)
    assert first is not None and not problems
    assert len(list(cache.glob("dsx7e-*.pickle"))) == 1
    _no_parsing(monkeypatch)
    again, _ = loader.read_profile(copy)
    assert again is not None and again.entries == first.entries and again.path == copy


def test_an_edited_file_is_parsed_again_and_replaces_its_old_compiled_form(cache, copy, monkeypatch):
    loader.read_profile(copy)
    text = copy.read_text()
    copy.write_text(text.replace("name: Load inertia ratio", "name: Inertia ratio of the load", 1))
    edited, _ = loader.read_profile(copy)
    assert edited is not None and edited.entry("Pn004").name == "Inertia ratio of the load"
    assert len(list(cache.glob("dsx7e-*.pickle"))) == 1


def test_a_damaged_cache_file_is_rebuilt(cache, copy):
    loader.read_profile(copy)
    (stored,) = cache.glob("dsx7e-*.pickle")
    stored.write_bytes(b"not a pickle")
    profile, _ = loader.read_profile(copy)
    assert profile is not None and profile.entry("Pn004").code == "Pn004"


def test_an_unwritable_cache_is_no_error(tmp_path, monkeypatch, copy):
    blocker = tmp_path / "file"
    blocker.write_text("")
    monkeypatch.setenv("SERVOTOOL_CACHE_DIR", str(blocker / "cache"))  # a folder below a file: cannot exist
    profile, problems = loader.read_profile(copy)
    assert profile is not None and not problems


def test_a_broken_profile_is_reported_from_the_cache_too(cache, copy):
    copy.write_text(copy.read_text().replace("id: dsx7e", "id: 7", 1))
    first = loader.read_profile(copy)
    assert first[0] is None and first[1]
    assert loader.read_profile(copy) == first
