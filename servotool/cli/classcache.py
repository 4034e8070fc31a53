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

# Entries kept: far more than all the commands define together; beyond it (texts of older versions of the
# classes) the file is rewritten with only what the last process used.
MAX_ENTRIES = 3000


class ClassCache:
    """Compiled dataclass sources by text, loaded from and saved to one file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.code: dict[str, CodeType] = _read(path)
        self.used: dict[str, CodeType] = {}
        self.compiled = 0           # texts this process had to compile (none when the cache knew them all)
        self.saving = False         # saved at exit (a servotool command)

    def exec(self, source: Any, globals: dict[str, Any] | None = None, locals: Any = None, **options: Any) -> None:
        """`exec` as dataclasses calls it (any later keyword, such as closure, passed on), with a text's code from
        the cache."""
        if globals is None:         # exec's own default: the caller's globals (and locals)
            frame = sys._getframe(1)
            globals, locals = frame.f_globals, frame.f_locals if locals is None else locals
        if isinstance(source, str):
            code = self.code.get(source)
            if type(code) is not CodeType:
                # dont_inherit: compiled as dataclasses compiles it, without this module's `from __future__`
                code = self.code[source] = compile(source, "<string>", "exec", dont_inherit=True)
                self.compiled += 1
            self.used[source] = code
            source = code
        builtins.exec(source, globals, locals, **options)

    def save(self) -> None:
        """Write the file when this process compiled anything new."""
        if not self.compiled:
            return
        keep = self.code if len(self.code) <= MAX_ENTRIES else self.used
        try:
            write_atomic(self.path, MAGIC_NUMBER + marshal.dumps(keep), durable=False)
        except (OSError, ValueError):       # ValueError: marshal met something it cannot write
            pass


def _read(path: Path) -> dict[str, CodeType]:
    try:
        data = path.read_bytes()
        if data.startswith(MAGIC_NUMBER) and isinstance(code := marshal.loads(data[len(MAGIC_NUMBER):]), dict):
            return code
    except Exception:       # missing, unreadable, damaged (marshal raises EOFError, ValueError, TypeError)
        pass
    return {}


def install() -> ClassCache:
    """Make dataclasses compile through the cache from now on in this process (once)."""
    current = getattr(dataclasses, "exec", None)
    if isinstance(getattr(current, "__self__", None), ClassCache):
        return current.__self__
    optimized = f"-O{sys.flags.optimize}" if sys.flags.optimize else ""      # as .pyc files: -O keeps its own
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
