"""Dataclass methods compiled once: the next process takes them from the cache, and the classes are the same."""

from __future__ import annotations

import dataclasses
import inspect
import json
import marshal
import os
import subprocess
import sys
from importlib.util import MAGIC_NUMBER
from pathlib import Path

import pytest

from servotool.cli.classcache import ClassCache

ROOT = Path(__file__).resolve().parents[2]

PROBE = """
import atexit, dataclasses, json, sys
def report():
    cache = dataclasses.exec.__self__
    sys.stderr.write("CACHE " + json.dumps([cache.compiled, len(cache.used)]) + "\\n")
sys.argv = ["servotool", *sys.argv[1:]]
from servotool.cli.main import run
atexit.register(report)
run()
"""


def compiled_and_used(env: dict[str, str]) -> list[int]:
    r = subprocess.run(
        [sys.executable, "-c", PROBE, "--port", "sim", "param", "get", "Pn004"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, **env},
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    return json.loads(next(x for x in r.stderr.splitlines() if x.startswith("CACHE ")).removeprefix("CACHE "))


def test_a_second_one_shot_compiles_no_dataclass(sim_dir, tmp_path):
    env = {"SERVOTOOL_CACHE_DIR": str(tmp_path / "cache")}
    # a program that only imports the CLI (a test run) uses the cache but leaves the file to the commands
    subprocess.run(
        [
            sys.executable,
            "-c",
            "import dataclasses, servotool.cli.main; assert dataclasses.exec.__self__.compiled > 40",
        ],
        check=True,
        cwd=ROOT,
        env={**os.environ, **env},
    )
    assert not list((tmp_path / "cache").glob("dataclasses-*"))
    compiled, used = compiled_and_used(env)
    assert compiled >= 40 and used == compiled
    assert compiled_and_used(env) == [0, used]


def define(cache: ClassCache, monkeypatch: pytest.MonkeyPatch) -> type:
    monkeypatch.setattr(dataclasses, "exec", cache.exec, raising=False)

    @dataclasses.dataclass(frozen=True)
    class Point:
        x: int
        y: float = 0.5
        tags: list[str] = dataclasses.field(default_factory=list)

    monkeypatch.undo()
    return Point


def test_cached_code_makes_the_same_class(tmp_path, monkeypatch):
    first = ClassCache(tmp_path / "c.marshal")
    a = define(first, monkeypatch)
    assert first.compiled > 0
    first.save()
    second = ClassCache(tmp_path / "c.marshal")
    b = define(second, monkeypatch)
    assert second.compiled == 0 and second.used.keys() == first.used.keys()
    p = b(1, tags=["t"])
    assert repr(p) == "define.<locals>.Point(x=1, y=0.5, tags=['t'])"
    assert p == b(1, 0.5, ["t"]) and p != b(2) and hash(b(1, 0.5, ())) == hash(b(1, 0.5, ()))  # type: ignore[arg-type]
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.x = 3  # type: ignore[misc]
    # compiled as dataclasses compiles it: the annotations are the fields' ('int' here: this module's future
    # import), not the generated names that `from __future__ import annotations` in classcache would leave
    assert inspect.signature(b).parameters["x"].annotation == inspect.signature(a).parameters["x"].annotation == "int"
    assert b.__init__.__code__.co_filename == "<string>"


def test_a_damaged_or_foreign_cache_file_is_ignored_and_rewritten(tmp_path, monkeypatch):
    path = tmp_path / "c.marshal"
    for junk in (
        b"",
        b"not marshal at all",
        b"\x00\x00\r\n" + b"\xff" * 40,
        MAGIC_NUMBER + marshal.dumps({__name__: b"junk", "other": 5}),
    ):
        path.write_bytes(junk)
        cache = ClassCache(path)
        assert cache.known() == {}
        assert define(cache, monkeypatch)(1).y == 0.5
        cache.save()
        assert ClassCache(path).known().keys() == cache.used.keys()


def test_each_module_s_classes_are_unpacked_only_when_it_defines_one(tmp_path, monkeypatch):
    path = tmp_path / "c.marshal"
    first = ClassCache(path)
    define(first, monkeypatch)
    first.save()
    stored = marshal.loads(path.read_bytes()[len(MAGIC_NUMBER) :])
    assert list(stored) == [__name__]
    stored["some.other.module"] = b"damaged, and never unpacked by this test"
    path.write_bytes(MAGIC_NUMBER + marshal.dumps(stored))
    second = ClassCache(path)
    define(second, monkeypatch)
    assert second.compiled == 0 and list(second._modules) == [__name__]
