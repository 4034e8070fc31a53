"""Trace files: captures to CSV (a commented header naming the drive, the line and the trigger, then one column per
entry with its unit) and back; any servotool CSV (trace, `monitor --csv`, `tune inertia --save-trace`) read as time
series for plotting."""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.errors import UsageError
from servotool.files import read_text, write_atomic
from servotool.model.codec import as_held
from servotool.model.profile import Entry
from servotool.model.quantity import quantity
from servotool.ops.trace import Capture

TIME_COLUMNS = ("t_s", "elapsed_s")
# `tune inertia --save-trace` names its unit after an underscore.
_SUFFIX_UNITS = {"rpm": "rpm", "pct": "%", "rev": "rev", "s": "s", "nm": "N·m", "ms": "ms"}
_BRACKET = re.compile(r"^(.*?)\s*\[(.*)\]\s*$")


def column_name(entry: Entry) -> str:
    return f"{entry.code} [{entry.unit}]" if entry.unit else entry.code


def trace_csv(captures: list[Capture], entries: list[Entry], about: list[str]) -> str:
    """The CSV text: '# ' lines (about, then each capture's timing before its rows), a header, the rows."""
    buf = io.StringIO()
    for line in about:
        buf.write(f"# {line}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["capture", "t_s", *[column_name(e) for e in entries]])
    for cap in captures:
        buf.write(f"# capture {cap.index}: {cap.timing.describe()}, {cap.pre_samples} before the trigger\n")
        for i, t in enumerate(cap.t):
            w.writerow([cap.index, f"{t:.5f}", *[_value(cap.values[e.code][i]) for e in entries]])
    return buf.getvalue()


def _value(v: float) -> str:
    """Exact for counts (a 32-bit position must not lose digits), short for scaled values."""
    return str(int(v)) if v.is_integer() and abs(v) < 2**53 else f"{v:.10g}"


def write_trace(
    path: Path, captures: list[Capture], entries: list[Entry], about: list[str], replace: bool = False
) -> None:
    """Write captures atomically (a new file unless replace)."""
    try:
        write_atomic(path, trace_csv(captures, entries, about), replace=replace, durable=False)
    except FileExistsError:
        raise UsageError(f"{path} exists; pass --force to replace it") from None
    except OSError as exc:
        raise UsageError(f"cannot write {path}: {exc.strerror or exc}") from None


def check_writable(path: Path, replace: bool) -> None:
    """Refuse an output path before anything is measured."""
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise UsageError(f"cannot write {path}: it is a directory")
    if path.exists() and not replace:
        raise UsageError(f"{path} exists; pass --force to replace it")
    if not parent.is_dir():
        raise UsageError(f"cannot write {path}: {parent} is not a folder")


def capture_json(cap: Capture, entries: list[Entry]) -> dict[str, Any]:
    tm = cap.timing
    return {
        "capture": cap.index,
        "samples": tm.samples,
        "pre_trigger_samples": cap.pre_samples,
        "rate": quantity(_num(tm.rate_hz), "Hz"),
        "jitter": quantity(_num(tm.jitter_ms), "ms"),
        "max_interval": quantity(_num(tm.max_gap_ms), "ms"),
        "t": {"unit": "s", "values": [round(t, 5) for t in cap.t]},
        "values": {e.code: {"unit": e.unit, "values": [as_held(e, v) for v in cap.values[e.code]]} for e in entries},
    }


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else round(x, 4)


@dataclass
class Series:
    name: str  # the code or column name without its unit
    unit: str
    values: list[float]

    @property
    def label(self) -> str:
        return f"{self.name} [{self.unit}]" if self.unit else self.name


@dataclass
class TimeTable:
    """A CSV of time series: the time column, the series, the '# ' header lines, and capture numbers (if any)."""

    path: Path
    time_name: str
    t: list[float]
    series: list[Series]
    about: list[str] = field(default_factory=list)
    capture: list[int] = field(default_factory=list)

    def segments(self) -> list[tuple[int, list[int]]]:
        """(capture number, row indices) of each capture; one segment numbered 0 for a file without captures."""
        if not self.capture:
            return [(0, list(range(len(self.t))))]
        found: dict[int, list[int]] = {}
        for i, c in enumerate(self.capture):
            found.setdefault(c, []).append(i)
        return list(found.items())

    def select(self, names: list[str]) -> TimeTable:
        """Only the named series (by code or full label); UsageError for a name the file lacks."""
        if not names:
            return self
        by = {s.name.lower(): s for s in self.series} | {s.label.lower(): s for s in self.series}
        missing = [n for n in names if n.lower() not in by]
        if missing:
            raise UsageError(
                f"{self.path} has no column {', '.join(missing)} (it has {', '.join(s.name for s in self.series)})"
            )
        return TimeTable(self.path, self.time_name, self.t, [by[n.lower()] for n in names], self.about, self.capture)


def capture_table(cap: Capture, entries: list[Entry], name: str = "capture") -> TimeTable:
    """A capture as a time table (to draw it without a file)."""
    return TimeTable(
        Path(name),
        "t_s",
        cap.t,
        [Series(e.code, e.unit, cap.values[e.code]) for e in entries],
        capture=[cap.index] * len(cap.t),
    )


def split_unit(header: str) -> tuple[str, str]:
    """'Un000 [rpm]' -> ('Un000', 'rpm'); 'speed_rpm' -> ('speed', 'rpm'); anything else has no unit."""
    if m := _BRACKET.match(header):
        return m.group(1).strip(), m.group(2).strip()
    stem, _, suffix = header.rpartition("_")
    if stem and suffix.lower() in _SUFFIX_UNITS:
        return stem, _SUFFIX_UNITS[suffix.lower()]
    return header.strip(), ""


def read_table(path: Path) -> TimeTable:
    """Read a trace, monitor or tune CSV; UsageError (one line) for anything that is not one."""
    text = read_text(path)
    about = [line[1:].strip() for line in text.splitlines() if line.startswith("#")]
    rows = list(csv.reader(line for line in text.splitlines() if line.strip() and not line.startswith("#")))
    if not rows:
        raise UsageError(f"{path} has no rows")
    header = rows[0]
    time_col = next((i for i, h in enumerate(header) if h.strip() in TIME_COLUMNS), None)
    if time_col is None:
        raise UsageError(
            f"{path} has no time column ({' or '.join(TIME_COLUMNS)}): not a servotool trace or monitor CSV"
        )
    skip = {time_col} | {i for i, h in enumerate(header) if h.strip() in ("capture", "timestamp")}
    cap_col = next((i for i, h in enumerate(header) if h.strip() == "capture"), None)
    cols = [i for i in range(len(header)) if i not in skip]
    t: list[float] = []
    data: list[list[float]] = [[] for _ in cols]
    capture: list[int] = []
    for n, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise UsageError(f"{path}: row {n} has {len(row)} fields, the header {len(header)}")
        try:
            t.append(float(row[time_col]))
            for k, i in enumerate(cols):
                data[k].append(float(row[i]) if row[i].strip() else math.nan)
            if cap_col is not None:
                capture.append(int(row[cap_col]))
        except ValueError:
            raise UsageError(f"{path}: row {n} holds a value that is not a number") from None
    if not t:
        raise UsageError(f"{path} has a header but no samples")
    series = [Series(*split_unit(header[i]), values=data[k]) for k, i in enumerate(cols)]
    return TimeTable(path, header[time_col], t, series, about, capture)
