"""Compiled profiles: a parsed profile is kept in the cache folder keyed by the file's content and reused; the
cache is data (JSON with a content hash), so a file planted there is refused, never run (issue 30 item 9)."""

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
    assert len(list(cache.glob("dsx7e-*.json"))) == 1
    _no_parsing(monkeypatch)
    again, _ = loader.read_profile(copy)
    assert again is not None and again.entries == first.entries and again.path == copy


def test_an_edited_file_is_parsed_again_and_replaces_its_old_compiled_form(cache, copy, monkeypatch):
    loader.read_profile(copy)
    text = copy.read_text()
    copy.write_text(text.replace("name: Load inertia ratio", "name: Inertia ratio of the load", 1))
    edited, _ = loader.read_profile(copy)
    assert edited is not None and edited.entry("Pn004").name == "Inertia ratio of the load"
    assert len(list(cache.glob("dsx7e-*.json"))) == 1


def test_a_damaged_cache_file_is_rebuilt(cache, copy):
    loader.read_profile(copy)
    (stored,) = cache.glob("dsx7e-*.json")
    stored.write_bytes(b"not JSON\n{")
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


def test_the_cache_round_trips_every_shipped_profile(cache):
    """What comes from the cache is what the schema built: every entry, role, alarm and identity check."""
    for pid in loader.builtin_ids():
        path = loader.builtin_dir() / f"{pid}.yaml"
        fresh, _ = loader.read_profile(path)
        cached, _ = loader.read_profile(path)
        assert len(list(cache.glob(f"{pid}-*.json"))) == 1
        assert cached is not fresh and cached == fresh, pid


class _Payload:
    """What a pickle runs on loading: here it leaves a marker file."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def test_a_planted_pickle_or_marshal_file_is_never_run_and_a_tampered_json_is_not_used(cache, copy, tmp_path):
    import marshal
    import pickle

    loader.read_profile(copy)
    (stored,) = cache.glob("dsx7e-*.json")
    key = stored.name.removeprefix("dsx7e-").removesuffix(".json")
    # the pickle-era name of this very file, and marshal's, each holding code that runs when loaded
    markers = [tmp_path / "ran-pickle", tmp_path / "ran-marshal"]
    (cache / f"dsx7e-{key}.pickle").write_bytes(pickle.dumps(_Payload(markers[0])))
    code = compile(f"open({str(markers[1])!r}, 'w')", "planted", "exec")
    (cache / f"dsx7e-{key}.marshal").write_bytes(marshal.dumps(code))
    # the JSON itself, edited to move Pn004 to another address (its hash left as it was)
    header, body = stored.read_bytes().split(b"\n", 1)
    tampered = body.replace(b'"Pn004","Pn","Load inertia ratio",8196', b'"Pn004","Pn","Load inertia ratio",8197')
    assert tampered != body
    stored.write_bytes(header + b"\n" + tampered)
    profile, problems = loader.read_profile(copy)
    assert profile is not None and not problems
    assert profile.entry("Pn004").address == 0x2004  # from the YAML, not the edited cache
    assert not any(m.exists() for m in markers)
    header, body = stored.read_bytes().split(b"\n", 1)  # rebuilt: the YAML's profile again, the pickle gone
    assert b"8197" not in body and not (cache / f"dsx7e-{key}.pickle").exists()


def test_a_cache_file_with_a_matching_hash_but_another_key_is_not_used(cache, copy, tmp_path):
    """A compiled profile copied from another file (or written by other code) has a valid hash but not the key."""
    import hashlib
    import json

    other = tmp_path / "other" / "dsx7e.yaml"
    other.parent.mkdir()
    other.write_text(copy.read_text().replace("name: Load inertia ratio", "name: Planted", 1))
    loader.read_profile(other)
    (planted,) = cache.glob("dsx7e-*.json")
    planted_bytes = planted.read_bytes()
    head, body = planted_bytes.split(b"\n", 1)
    assert json.loads(head)["sha256"] == hashlib.sha256(body).hexdigest() and b"Planted" in body
    loader.read_profile(copy)  # its own compiled file replaces the other's (same file name stem)
    (mine,) = cache.glob("dsx7e-*.json")
    mine.write_bytes(planted_bytes)
    profile, _ = loader.read_profile(copy)
    assert profile.entry("Pn004").name == "Load inertia ratio"


@pytest.mark.skipif(not hasattr(__import__("os"), "geteuid"), reason="file owners are POSIX")
def test_a_cache_file_others_may_write_is_not_used(cache, copy, monkeypatch):
    loader.read_profile(copy)
    (stored,) = cache.glob("dsx7e-*.json")
    stored.chmod(0o666)
    monkeypatch.setattr(loader, "parse_yaml", lambda *_a: (_ for _ in ()).throw(RuntimeError("parsed")))
    with pytest.raises(RuntimeError, match="parsed"):
        loader.read_profile(copy)
