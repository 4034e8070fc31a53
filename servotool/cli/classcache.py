"""Dataclass methods compiled once and kept between runs, as Python keeps a module's bytecode in .pyc files.

`@dataclass` writes each class's `__init__`, `__repr__`, `__eq__`, ... as source text and compiles it, in every
process: a one-shot `param get` defines ~55 dataclasses (servotool's, typer's, pymodbus', filelock's), and that
compiling was a fifth of its start-up. Here the code objects are kept in the cache folder, keyed by the exact
source text and the Python that compiled them; the next process executes them instead of compiling the text again.
The same text compiles to the same code, so the classes are the same. A damaged or foreign cache file is ignored
(and rewritten); one that cannot be written costs only the time saved.
"""

from __future__ import annotations

import atexit
import builtins
import dataclasses
import marshal
import sys
from importlib.util import MAGIC_NUMBER
from pathlib import Path
from types import CodeType
from typing import Any

from servotool.files import cache_dir, write_atomic

# Bytes kept: far more than all the commands define together (~0.8 MB); beyond it (texts of older versions of the
# classes) the file is rewritten with only the modules the last process used.
MAX_BYTES = 4 << 20


class ClassCache:
    """Compiled dataclass sources by text, grouped by the module that defines the class, loaded from and saved to
    one file. A module's group is unpacked when the module defines its first class: a command pays only for the
    modules it loads, not for every command's."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._stored: dict[str, bytes] = _read(path)  # module -> its {text: code}, marshalled
        self._modules: dict[str, dict[str, CodeType]] = {}  # the groups unpacked (or begun) by this process
        self.used: dict[str, CodeType] = {}
        self.compiled = 0  # texts this process had to compile (none when the cache knew them all)
        self.saving = False  # saved at exit (a servotool command)

    def exec(self, source: Any, globals: dict[str, Any] | None = None, locals: Any = None, **options: Any) -> None:
        """`exec` as dataclasses calls it (any later keyword, such as closure, passed on), with a text's code from
        the cache."""
        if globals is None:  # exec's own default: the caller's globals (and locals)
            frame = sys._getframe(1)
            globals, locals = frame.f_globals, frame.f_locals if locals is None else locals
        if isinstance(source, str):
            codes = self._module(str(globals.get("__name__", "")))
            code = codes.get(source)
            if type(code) is not CodeType:
                # dont_inherit: compiled as dataclasses compiles it, without this module's `from __future__`
                code = codes[source] = compile(source, "<string>", "exec", dont_inherit=True)
                self.compiled += 1
            self.used[source] = code
            source = code
        builtins.exec(source, globals, locals, **options)

    def _module(self, name: str) -> dict[str, CodeType]:
        if (codes := self._modules.get(name)) is None:
            try:
                codes = marshal.loads(self._stored[name]) if name in self._stored else {}
            except Exception:  # damaged (marshal raises EOFError, ValueError, TypeError)
                codes = {}
            self._modules[name] = codes = codes if isinstance(codes, dict) else {}
        return codes

    def known(self) -> dict[str, CodeType]:
        """Every compiled text the file and this process have, of every module."""
        return {text: code for name in [*self._stored, *self._modules] for text, code in self._module(name).items()}

    def save(self) -> None:
        """Write the file when this process compiled anything new."""
        if not self.compiled:
            return
        try:
            mine = {name: marshal.dumps(codes) for name, codes in self._modules.items() if codes}
            stored = {**self._stored, **mine}
            if sum(len(b) for b in stored.values() if isinstance(b, bytes)) > MAX_BYTES:
                stored = mine
            write_atomic(self.path, MAGIC_NUMBER + marshal.dumps(stored), durable=False)
        except (OSError, ValueError):  # ValueError: marshal met something it cannot write
            pass


def _read(path: Path) -> dict[str, bytes]:
    try:
        data = path.read_bytes()
        if data.startswith(MAGIC_NUMBER) and isinstance(stored := marshal.loads(data[len(MAGIC_NUMBER) :]), dict):
            return stored
    except Exception:  # missing, unreadable, damaged (marshal raises EOFError, ValueError, TypeError)
        pass
    return {}


def install() -> ClassCache:
    """Make dataclasses compile through the cache from now on in this process (once)."""
    current = getattr(dataclasses, "exec", None)
    if isinstance(getattr(current, "__self__", None), ClassCache):
        return current.__self__
    optimized = f"-O{sys.flags.optimize}" if sys.flags.optimize else ""  # as .pyc files: -O keeps its own
    cache = ClassCache(cache_dir() / f"dataclasses-{sys.implementation.cache_tag}{optimized}.marshal")
    dataclasses.exec = cache.exec  # type: ignore[attr-defined]   # shadows the builtin for that module only
    return cache


def save_at_exit() -> None:
    """Save what this process compiles when it ends: called by a servotool command only, so that a program that
    imports the CLI (a test run, with its own dataclasses by the hundred) does not fill the file every command
    reads."""
    cache = install()
    if not cache.saving:
        cache.saving = True
        atexit.register(cache.save)
