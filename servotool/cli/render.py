"""Output helpers shared by the commands: tables on stdout, messages on stderr, JSON.

Every table printed on `out` is fitted to the width: text columns (names, descriptions) wrap but keep at least
NAME_MIN columns, the least useful columns go first (DROP_ORDER, or the table's own `drop`), and a table that
still does not fit is shown as one block per row. Piped output takes the width of the terminal the user looks at
(COLUMNS, else stderr's terminal) and, with no terminal at all, is not wrapped.

rich draws what needs it (a terminal's styles, a table to fit, live views, progress) and is imported then; plain
lines and plain tables (cli/grid.py) are written as they are, so that a one-shot command starts without it.
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from functools import cache
from typing import IO, TYPE_CHECKING, Any

from servotool.cli.grid import Grid

if TYPE_CHECKING:
    from rich.console import Console, Group
    from rich.table import Table

NAME_MIN = 20  # a wrapped name or description keeps at least this many columns: readable
UNLIMITED = 10_000  # "no width": nothing wraps
# text columns: these wrap
WRAP = {"Name", "Description", "Meaning", "Why unverified", "Why", "Note", "Result", "Function", "Recorded"}
# Columns dropped first when a table is too wide, least useful first; tables may give their own order.
DROP_ORDER = (
    "Address",
    "Type",
    "Class",
    "Version",
    "Vendor",
    "Unverified",
    "Effect",
    "Trend",
    "Min",
    "Max",
    "Default",
    "Needs",
    "",
)
RIGHT = ("Value", "Default", "Min", "Max", "Address")


def _stdout_width() -> int | None:
    """The width for stdout: None (rich asks the terminal) on a terminal; when piped, COLUMNS or stderr's
    terminal, and no limit without any terminal (a file, a script's pipe)."""
    if sys.stdout.isatty():
        return None
    if (columns := os.environ.get("COLUMNS", "")).isdigit() and int(columns) > 0:
        return int(columns)
    try:
        return os.get_terminal_size(sys.stderr.fileno()).columns
    except (OSError, ValueError, AttributeError):
        return UNLIMITED


def text_width(stderr: bool = False) -> int:
    """The width plain text is wrapped to on stdout (or stderr): its terminal's, else COLUMNS; piped stdout takes
    stderr's terminal, and with no terminal at all nothing is wrapped (UNLIMITED)."""
    stream = sys.stderr if stderr else sys.stdout
    if _isatty(stream):
        return _columns(stream)
    if (columns := os.environ.get("COLUMNS", "")).isdigit() and int(columns) > 0:
        return int(columns)
    if not stderr and _isatty(sys.stderr):
        return _columns(sys.stderr)
    return UNLIMITED


def _columns(stream: IO[str]) -> int:
    """A terminal's width; one that reports none (0, a pty nobody sized) is read as COLUMNS, else 80, as rich does."""
    try:
        columns = os.get_terminal_size(stream.fileno()).columns
    except (OSError, ValueError, AttributeError):
        columns = 0
    if columns > 0:
        return columns
    given = os.environ.get("COLUMNS", "")
    return int(given) if given.isdigit() and int(given) > 0 else 80


def _isatty(stream: IO[str]) -> bool:
    try:
        return stream.isatty()
    except (ValueError, AttributeError):
        return False


def cells(text: str) -> int:
    """Columns a text takes on a terminal: East Asian wide characters take two (the manuals' 本次 in a note)."""
    import unicodedata

    return sum(2 if unicodedata.east_asian_width(c) in "WF" else 1 for c in text)


def wrap(text: str, width: int | None = None, *, indent: str = "", hanging: str = "  ") -> str:
    """Text broken between words to fit `width` columns (default: stdout's text_width): the first line after
    `indent`, the rest after `indent` + `hanging`. A word longer than the width stays whole."""
    width = text_width() if width is None else width
    out: list[str] = []
    for paragraph in text.split("\n"):
        if cells(indent + paragraph) <= width:
            out.append(indent + paragraph)
            continue
        words = paragraph.lstrip(" ")
        lead = indent + paragraph[: len(paragraph) - len(words)]
        line, used = lead, cells(lead)
        for word in words.split(" "):
            size = cells(word)
            if line.strip() and used + 1 + size > width:
                out.append(line.rstrip(" "))
                line, used = lead + hanging + word, cells(lead + hanging) + size
            else:
                sep = " " if line.strip() else ""
                line, used = line + sep + word, used + len(sep) + size
        out.append(line.rstrip(" "))
    return "\n".join(out)


def _is_terminal(file: IO[str]) -> bool:
    """Whether rich would style what goes to `file` (its rule: TTY_COMPATIBLE, FORCE_COLOR, else isatty)."""
    if (compatible := os.environ.get("TTY_COMPATIBLE", "")) in ("0", "1"):
        return compatible == "1"
    if (force := os.environ.get("FORCE_COLOR")) is not None:
        return force != ""
    isatty = getattr(file, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # closed
        return False


@cache
def _fitting_console() -> type[Console]:
    from rich.console import Console
    from rich.table import Table

    class FittingConsole(Console):
        """A console that fits every table it prints to its width."""

        def print(self, *objects: Any, **kwargs: Any) -> None:  # type: ignore[override]
            super().print(*(fit(o, self.width) if isinstance(o, Grid | Table) else o for o in objects), **kwargs)

    return FittingConsole


def __getattr__(name: str) -> Any:
    """rich's classes as this module's attributes (render.Console, render.FittingConsole), loaded when asked for."""
    if name == "FittingConsole":
        return _fitting_console()
    if name == "Console":
        from rich.console import Console

        return Console
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _Stream:
    """stdout (`out`) or stderr (`err`) as a rich console whose console is made when first needed: until then a
    plain line or a plain table (cli/grid.py) that rich would print unchanged is written as it is. Once the console
    exists (a terminal's styles, a live view, progress), everything goes through it, in order."""

    def __init__(self, stderr: bool) -> None:
        self._stderr = stderr
        self._console: Console | None = None

    @property
    def console(self) -> Console:
        if self._console is None:
            if self._stderr:
                from rich.console import Console

                self._console = Console(stderr=True, highlight=False, soft_wrap=True, emoji=False)
            else:
                self._console = _fitting_console()(highlight=False, emoji=False, width=_stdout_width())
        return self._console

    @property
    def is_terminal(self) -> bool:
        return self._console.is_terminal if self._console is not None else _is_terminal(self._file())

    def __getattr__(self, name: str) -> Any:
        return getattr(self.console, name)

    def __enter__(self) -> Console:
        return self.console.__enter__()

    def __exit__(self, *exc: Any) -> None:
        self.console.__exit__(*exc)

    def _file(self) -> IO[str]:
        return sys.stderr if self._stderr else sys.stdout

    def print(self, *objects: Any, **kwargs: Any) -> None:
        objects = self._wrapped(objects, kwargs)
        text = self._plain(objects, kwargs) if self._console is None else None
        if text is None:
            self.console.print(*objects, **kwargs)
            return
        file = self._file()
        file.write(text)
        file.flush()

    def _wrapped(self, objects: tuple[Any, ...], kwargs: dict[str, Any]) -> tuple[Any, ...]:
        """A line of text broken between words to the stream's width (its terminal's, or COLUMNS), the rest of a
        long line indented: a terminal would break it anywhere, mid-word. Not wrapped without any width (a file, a
        script's pipe), nor text with markup, whose width is rich's to count."""
        if len(objects) != 1 or type(objects[0]) is not str or set(kwargs) - {"markup", "style"}:
            return objects
        if "[" in objects[0] and kwargs.get("markup", True) is not False:
            return objects
        width = text_width(self._stderr)
        return objects if width >= UNLIMITED else (wrap(objects[0], width),)

    def _plain(self, objects: tuple[Any, ...], kwargs: dict[str, Any]) -> str | None:
        """What rich would print for these, when it is plain text; None when rich must print it."""
        if len(objects) != 1 or set(kwargs) - {"markup", "style"}:
            return None
        file, (o,) = self._file(), objects
        if _is_terminal(file) and (not self._stderr or kwargs.get("style") or isinstance(o, Grid)):
            return None  # styles show, and stdout's width is the terminal's: rich's
        width = UNLIMITED if self._stderr else _stdout_width() or UNLIMITED
        if isinstance(o, Grid):
            utf = (getattr(file, "encoding", None) or "utf-8").lower().startswith("utf")  # else rich draws ASCII
            return o.plain(width) if utf else None
        if type(o) is not str or ("[" in o and kwargs.get("markup", True) is not False):
            return None
        lines = o.split("\n")
        if not all(line.isprintable() for line in lines):
            return None
        if width != UNLIMITED and not all(line.isascii() and len(line) <= width for line in lines):
            return None  # it would wrap
        return o + "\n"


out: Any = _Stream(stderr=False)
err: Any = _Stream(stderr=True)


class Verbosity:
    """Global -q/-v/--explain state."""

    level = 0  # -1 quiet, 0 normal, 1+ verbose
    explain = False  # cautions in full


def info(text: str) -> None:
    """A progress/status line on stderr (suppressed by --quiet)."""
    if Verbosity.level >= 0:
        err.print(text, markup=False)


def notice(text: str) -> None:
    """A line on stderr that --quiet does not hide (that the drive is simulated, for one)."""
    err.print(text, markup=False)


def safety(text: str) -> None:
    """A safety line on stderr: what stops the motor if this program stops and how far it can run on, a missing
    dead-man, wired inputs that do not act. Never hidden by --quiet (and given in --json by the command too)."""
    err.print(text, markup=False)


_UNVERIFIED = re.compile(r"(\S+) \((\w+)\): ")
_RELIES = re.compile(r"(.+?) relies on .*; unverified\b")  # "the dead-man (segment) relies on L..; unverified: ..."


def _short_caution(line: str) -> str:
    """A caution's one line: what it is about, without the manual's line numbers."""
    if m := _UNVERIFIED.match(line):
        return f"{m.group(1)} ({m.group(2).replace('_', ' ')}) is not confirmed by the manual"
    if m := _RELIES.match(line):
        return f"{m.group(1).replace('_', ' ')} is not confirmed by the manual"
    from servotool.cli.messages import plain  # the words' module, only once a caution is shown

    return plain(line.split(": ", 1)[0])


def caution(lines: Sequence[str]) -> None:
    """Cautions before something acts on a real drive: one line each (what it is about), the full text with
    --explain."""
    for line in lines:
        if not Verbosity.explain:
            line = _short_caution(line)
        err.print(f"servotool: caution: {line}", markup=False)
    if lines and not Verbosity.explain:
        err.print("servotool: (--explain shows why)", markup=False)


def warn(text: str) -> None:
    """A warning on stderr (shown with --quiet too); the manual's line numbers only with -v."""
    from servotool.cli.messages import plain

    err.print(f"servotool: warning: {plain(text, Verbosity.level > 0)}", markup=False)


_emitted = [False]
_streaming = [False]


def emit_json(data: Any) -> None:
    """One JSON document on stdout (one line where the command streams JSON lines: an error after them too)."""
    _emitted[0] = True
    sys.stdout.write(json.dumps(data, indent=None if _streaming[0] else 2, ensure_ascii=False, default=str) + "\n")
    sys.stdout.flush()


def emit_json_line(data: Any) -> None:
    """One object of a stream of JSON lines (monitor --json), written at once; the command's error, if any, is
    then one line as well."""
    _streaming[0] = True
    sys.stdout.write(json.dumps(data, ensure_ascii=False, default=str) + "\n")
    sys.stdout.flush()


def new_command() -> None:
    """Forget what the previous command printed (`servotool shell` runs many in one process): a JSON document or
    JSON lines of its own must not keep the next command's error from being a JSON object, or make it one line."""
    _emitted[0] = _streaming[0] = False


def json_emitted() -> bool:
    """Whether this command has printed a JSON document already (an error then adds none)."""
    return _emitted[0]


def table(*columns: str, title: str | None = None, drop: Sequence[str] | None = None) -> Grid:
    """A table of text cells (a rich Table where rich draws it); `drop` names the columns to give up first when it
    is too wide (default DROP_ORDER)."""
    t = Grid(title=title, drop=tuple(drop) if drop is not None else DROP_ORDER)
    for c in columns:
        t.add_column(c, justify="right" if c in RIGHT else "left", overflow="fold")
    return t


def _cells(t: Grid | Table, i: int) -> list[str]:
    return [str(c) for c in t.columns[i]._cells]


def _span(widths: Sequence[int]) -> int:
    """Width of a table with these column widths: one padding space either side, one rule between and around."""
    return sum(widths) + 3 * len(widths) + 1


def fit(t: Grid | Table, width: int) -> Grid | Table | Group:
    """The table as it fits `width` columns: as is, with text columns wrapped, without its least useful columns,
    or as one block per row."""
    from rich.cells import cell_len
    from rich.table import Table

    n = len(t.columns)
    body = [max((cell_len(c) for c in _cells(t, i)), default=0) for i in range(n)]
    head = [cell_len(str(c.header)) for c in t.columns]
    desired = [max(b, h) for b, h in zip(body, head, strict=True)]
    if _span(desired) <= width or n == 0:
        return t
    wraps = [str(c.header) in WRAP for c in t.columns]
    least = [
        max(1, min(d, NAME_MIN)) if w else max(b, min(h, 12), 1)
        for d, b, h, w in zip(desired, body, head, wraps, strict=True)
    ]
    keep = list(range(n))
    order = getattr(t, "drop", DROP_ORDER)
    for name in order:
        if _span([least[i] for i in keep]) <= width:
            break
        keep = [i for i in keep if str(t.columns[i].header) != name or wraps[i]]
    if _span([least[i] for i in keep]) > width:
        return _vertical(t, width)
    widths = {i: least[i] for i in keep}
    spare = width - _span(list(widths.values()))
    for i in sorted(keep, key=lambda i: not wraps[i]):  # text columns take the room first
        more = min(spare, desired[i] - widths[i])
        widths[i] += more
        spare -= more
    fitted = Table(title=t.title, show_lines=t.show_lines, header_style=t.header_style, title_justify=t.title_justify)
    for i in keep:
        c = t.columns[i]
        fitted.add_column(c.header, justify=c.justify, overflow="fold", width=widths[i], no_wrap=False)
    for row in zip(*(_cells(t, i) for i in keep), strict=True):
        fitted.add_row(*row)
    return fitted


def _vertical(t: Grid | Table, width: int) -> Group:
    """One block per row: the first cell, then 'Header: value' lines (for a table too wide for the screen)."""
    from rich.console import Group
    from rich.text import Text

    heads = [str(c.header) for c in t.columns]
    columns = [_cells(t, i) for i in range(len(heads))]
    lines: list[Text] = [Text(str(t.title), style="bold")] if t.title else []
    for r in range(len(columns[0]) if columns else 0):
        lines.append(Text(columns[0][r], style="bold"))
        for head, cells in zip(heads[1:], columns[1:], strict=True):
            if cells[r]:
                lines.append(Text(f"  {head or 'Mark'}: {cells[r]}"))
    return Group(*lines)


@contextmanager
def progress(label: str, total: int, enabled: bool = True) -> Iterator[Any]:
    """A progress bar with the rate and the time left on stderr (a terminal only, not with --quiet); yields a
    function advancing it by n."""
    if not enabled or Verbosity.level < 0 or not err.is_terminal:
        yield lambda n=1: None
        return
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        console=err,
        transient=True,
    ) as bar:
        task = bar.add_task(label, total=total)
        yield lambda n=1: bar.advance(task, n)


def trace_frame(sending: bool, data: bytes) -> None:
    """-v: every RTU frame in hex."""
    err.print(f"{'>>' if sending else '<<'} {data.hex(' ')}", markup=False, style="dim")
