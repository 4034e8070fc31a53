"""Parameter sets as CSV, for spreadsheets: written from a backup, read back into one (the value column counts).

The first row names the profile, model and unit; then a header and one row per parameter: code, name, value (in
engineering units, as `param set` takes it), unit, meaning (of an enum value), raw (the register integer, for
reference). A CSV is meant to be edited, so it carries no checksum; the value column is what a restore writes.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from servotool.errors import UsageError
from servotool.files import read_text
from servotool.model.codec import format_value, parse_value, raw_to_eng
from servotool.model.profile import Entry, Profile

MARK = "servotool parameter backup"
COLUMNS = ["code", "name", "value", "unit", "meaning", "raw"]


def value_text(entry: Entry, raw: int) -> str:
    """The value as `param set` takes it: the engineering number, or the manual's form for encoded values."""
    if entry.format != "dec":
        return format_value(entry, raw)
    eng = raw_to_eng(entry, raw)
    return str(eng)


def rows(profile: Profile, values: dict[str, int]) -> list[list[str]]:
    out = []
    for code, raw in values.items():
        e = profile.entry(code)
        out.append([e.code, e.name, value_text(e, raw), e.unit, e.enum.get(raw, ""), str(raw)])
    return out


def to_csv(profile: Profile, meta: dict[str, str], values: dict[str, int]) -> str:
    """The CSV text: the identifying first row (meta as key=value), the header, one row per parameter."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([MARK, *(f"{k}={v}" for k, v in meta.items())])
    w.writerow(COLUMNS)
    w.writerows(rows(profile, values))
    return buf.getvalue()


def _meta(path: Path) -> tuple[dict[str, str], list[list[str]]]:
    table = list(csv.reader(io.StringIO(read_text(path))))
    if not table or not table[0] or table[0][0] != MARK:
        raise UsageError(f"{path}: not a servotool CSV backup (its first row must start with '{MARK}')")
    meta = dict(cell.split("=", 1) for cell in table[0][1:] if "=" in cell)
    return meta, table[1:]


def profile_of(path: Path) -> str | None:
    try:
        return _meta(path)[0].get("profile")
    except UsageError:
        return None


def read(path: Path, profile: Profile, *, force: bool = False) -> tuple[dict[str, str], dict[str, int], list[str]]:
    """A CSV backup's first-row facts, its values (each parsed and range-checked against the profile; nothing is
    sent) and warnings."""
    meta, table = _meta(path)
    if not table or [c.strip().lower() for c in table[0][:3]] != COLUMNS[:3]:
        raise UsageError(f"{path}: the second row must be the header {','.join(COLUMNS)}")
    warnings = [f"{path}: a CSV backup has no checksum: its values are used as they are"]
    if meta.get("profile") != profile.id or meta.get("model") != profile.model:
        msg = (
            f"{path}: backup of a {meta.get('model')} ({meta.get('profile')}), not of this {profile.model} "
            f"({profile.id})"
        )
        if not force:
            raise UsageError(msg + "; --force to restore anyway")
        warnings.append(msg)
    values: dict[str, int] = {}
    for n, row in enumerate(table[1:], start=3):
        if not row or not "".join(row).strip():
            continue
        entry = profile.find(row[0].strip())
        if entry is None or entry.cls != "Pn":
            raise UsageError(f"{path}: line {n}: unknown parameter {row[0]} for profile {profile.id}")
        try:
            values[entry.code] = parse_value(entry, row[2] if len(row) > 2 else "")
        except UsageError as exc:
            raise UsageError(f"{path}: line {n}: {exc}") from None
    return meta, values, warnings
