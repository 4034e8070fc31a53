"""Single keys from the terminal, on every OS: cbreak mode through termios on POSIX, msvcrt on Windows.

The platform's terminal modules are imported only inside the functions that use them, so that the CLI imports
(and every command but an interactive one runs) where they do not exist.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager

# Key sequences -> the action names callers map to what they do.
POSIX_KEYS = {"\x1b[C": "fwd", "\x1b[D": "rev", "d": "fwd", "a": "rev", " ": "stop", "q": "quit", "\x1b": "quit"}
WINDOWS_KEYS = {
    "\xe0M": "fwd",
    "\xe0K": "rev",
    "\x00M": "fwd",
    "\x00K": "rev",
    "d": "fwd",
    "a": "rev",
    " ": "stop",
    "q": "quit",
    "\x1b": "quit",
}

KeyReader = Callable[[], "str | None"]


def last_key(data: str, keys: dict[str, str]) -> str:
    """The last known key in what the terminal sent since the last poll (a held key arrives repeated); "" if none."""
    found, i = "", 0
    names = sorted(keys, key=len, reverse=True)
    while i < len(data):
        match = next((k for k in names if data.startswith(k, i)), None)
        if match is None:
            i += 1
            continue
        found, i = keys[match], i + len(match)
    return found


@contextmanager
def raw_keys() -> Iterator[KeyReader]:
    """A non-blocking key reader: yields a function returning the last of fwd/rev/stop/quit pressed since the last
    call (a held key queues repeats), "" for another key and None when no key was pressed. The terminal is
    restored however the block is left."""
    if sys.platform == "win32":
        yield windows_key
        return
    with _posix_keys() as key:
        yield key


def windows_key() -> str | None:
    """The last key waiting on the Windows console, or None when none is waiting."""
    import msvcrt

    if not msvcrt.kbhit():  # type: ignore[attr-defined]
        return None
    data = ""
    while msvcrt.kbhit():  # type: ignore[attr-defined]   # a held key queues repeats: take them all
        data += msvcrt.getwch()  # type: ignore[attr-defined]
        if data[-1] in ("\x00", "\xe0"):  # an arrow key arrives as a prefix and its scan code
            data += msvcrt.getwch()  # type: ignore[attr-defined]
    return last_key(data, WINDOWS_KEYS)


@contextmanager
def _posix_keys() -> Iterator[KeyReader]:
    """cbreak mode on stdin; restores the terminal however we leave."""
    import select
    import termios
    import tty

    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    tty.setcbreak(fd)

    def key() -> str | None:
        if not select.select([fd], [], [], 0)[0]:
            return None
        return last_key(os.read(fd, 64).decode(errors="ignore"), POSIX_KEYS)

    try:
        yield key
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
