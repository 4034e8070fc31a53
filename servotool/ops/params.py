"""Parameter operations built on Drive: select, plan (validate and read current values), the one write path."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import nullcontext
from dataclasses import dataclass, field

from servotool.drive import Drive, WriteResult
from servotool.errors import ServoError, UnknownName, UsageError
from servotool.model.codec import format_value, split_field
from servotool.model.lookup import COMMON_GROUPS, group_members, suggest
from servotool.model.profile import Entry, Profile


def select(profile: Profile, *, group: str | None = None, classes: tuple[str, ...] = ("Pn",)) -> list[Entry]:
    """Readable entries of the given classes (and group: its id in any case, or a common name such as gain or
    speed, see model.lookup), in profile order."""
    entries = profile.entries
    if group is not None:
        members = group_members(profile.entries, group)
        if members is None:
            known = sorted({e.group for e in profile.entries if e.group} | set(COMMON_GROUPS))
            raise UnknownName("group", group, profile.id, suggest(group, known), known)
        entries = members
    return [e for e in entries if e.cls in classes and e.readable]


def read_settings(drive: Drive, progress: Callable[[int], None] | None = None) -> dict[str, int]:
    """Every readable parameter as the drive holds it (code -> raw, coalesced); entries it lacks are left out (and
    listed in drive.missing). An entry a raised line holds for the command (ops.boost) reads as its original,
    which is what the drive keeps and gets back when the command ends."""
    from servotool.ops.boost import held_originals

    values = {r.entry.code: r.raw for r in drive.read_entries(select(drive.profile), partial=True, progress=progress)}
    values.update({code: raw for code, raw in held_originals(drive).items() if code in values})
    return values


@dataclass(frozen=True)
class PreparedSet:
    """Validated assignments with the drive's current values."""

    changes: list[tuple[Entry, int, int]]  # entry, old raw, new raw
    unchanged: list[tuple[Entry, int]]
    missing: list[Entry] = field(default_factory=list)  # with partial=True: entries the drive lacks, left out


def prepare_set(drive: Drive, assignments: list[str], *, raw: bool = False, partial: bool = False) -> PreparedSet:
    """Parse and range-check every CODE=VALUE, then read current values; nothing is written. partial=True leaves
    out (in `missing`) an entry the drive lacks instead of failing with NotOnDrive."""
    if not assignments:
        raise UsageError("nothing to set: give CODE=VALUE ...")
    parsed: dict[str, tuple[Entry, list[str]]] = {}
    fields_given: dict[str, set[str]] = {}
    for text in assignments:
        entry, _ = drive.parse_assignment(text, raw=raw)  # validates code/access/type/range before any I/O
        field = split_field(drive.profile, text.partition("=")[0])[1]
        if entry.code in parsed:
            # Several fields of one entry (Po175.C=2 Po175.D=3) make one write; anything else twice is a mistake.
            done = fields_given.get(entry.code)
            if field is None or done is None:
                raise UsageError(f"{entry.code} is given twice")
            if field in done:
                raise UsageError(f"{entry.code}.{field} is given twice")
            done.add(field)
        else:
            parsed[entry.code] = (entry, [])
            if field is not None:
                fields_given[entry.code] = {field}
        parsed[entry.code][1].append(text)
    readable = [e for e, _ in parsed.values() if e.readable]
    current = {r.entry.code: r.raw for r in drive.read_entries(readable, partial=partial)}
    missing = [e for e in readable if e.code not in current]
    changes: list[tuple[Entry, int, int]] = []
    unchanged: list[tuple[Entry, int]] = []
    for entry, texts in parsed.values():
        if entry.readable and entry.code not in current:
            continue
        old = current.get(entry.code)
        # Field input (Po001.Y=1, X=0) is relative to the drive's current value, so parse again with it.
        new = drive.parse_assignment(texts[0], raw=raw, current=old)[1]
        for text in texts[1:]:
            new = drive.parse_assignment(text, raw=raw, current=new)[1]
        if old == new:
            unchanged.append((entry, new))
        else:
            changes.append((entry, old if old is not None else new, new))
    return PreparedSet(changes, unchanged, missing)


def set_assignments(
    drive: Drive, assignments: list[str], *, raw: bool = False, save: bool | None = None
) -> tuple[PreparedSet, SetOutcome]:
    """`param set`: parse, read the current values and write them under the drive's EEPROM rule, all under the
    port's lock. A field (Po018.A=1) is written as the whole register read before it, so no other process may
    write that register between this read and this write: two field writes in two processes both land."""
    from servotool.ops.journal import port_lock

    with port_lock(drive):
        plan = prepare_set(drive, assignments, raw=raw)
        return plan, set_values(drive, plan, save)


def write_one(drive: Drive, entry: Entry, raw: int, old: int | None = None) -> WriteResult:
    """The one path every parameter write takes (set, restore, plans): write, then verify by read-back. A change
    made inside a batch of lasting writes goes into the drive's change log (ops.changelog)."""
    from servotool.ops import changelog

    [old] = changelog.before_write(drive, [(entry, old)])
    result = drive.write_verified(entry, raw, old)
    changelog.after_write(drive, [result])
    return result


def write_runs(drive: Drive, changes: list[tuple[Entry, int, int]]) -> list[list[tuple[Entry, int, int]]]:
    """Split changes (in the order given) into runs one request can carry: consecutive entries at adjacent
    addresses, when the drive takes FC16, up to its max_write registers. A single entry is a run of one."""
    limits = drive.profile.limits
    runs: list[list[tuple[Entry, int, int]]] = []
    for change in changes:
        entry = change[0]
        if runs and limits.write_multiple:
            run = runs[-1]
            last = run[-1][0]
            if (
                entry.address == last.address + last.words
                and sum(e.words for e, _, _ in run) + entry.words <= limits.max_write
            ):
                run.append(change)
                continue
        runs.append([change])
    return runs


def write_changes(drive: Drive, changes: list[tuple[Entry, int, int]]) -> list[WriteResult]:
    """Changed parameters (entry, old, new) in the fewest verified requests: adjacent ones in one FC16 request
    (write_runs), each run verified by one read-back; the others by write_one."""
    results: list[WriteResult] = []
    for run in write_runs(drive, sorted(changes, key=lambda c: c[0].address)):
        results.extend(write_run(drive, run))
    return results


def write_run(drive: Drive, run: list[tuple[Entry, int, int]]) -> list[WriteResult]:
    """One run of write_runs (entry, old, new): a lone entry by write_one, adjacent ones in one verified FC16
    request."""
    from servotool.ops import changelog

    if len(run) == 1:
        entry, old, new = run[0]
        return [write_one(drive, entry, new, old)]
    olds = changelog.before_write(drive, [(e, old) for e, old, _new in run])
    results = drive.write_block_verified([(e, new, old) for (e, _, new), old in zip(run, olds, strict=True)])
    changelog.after_write(drive, results)
    return results


def apply_set(drive: Drive, plan: PreparedSet) -> list[WriteResult]:
    """Write the planned changes in order, adjacent ones in one FC16 request (as the manuals' multi-register
    examples do), each verified by read-back. A failure names what was written before it."""
    results: list[WriteResult] = []
    for run in write_runs(drive, plan.changes):
        try:
            results.extend(write_run(drive, run))
        except ServoError as exc:
            raise _naming_written(exc, results, [e for e, _, _ in run]) from None
    return results


def _naming_written(exc: ServoError, written: list[WriteResult], unsure: list[Entry]) -> ServoError:
    """The error of a set that stopped midway, its message extended by what was written before it (same type and
    exit code); `exc.written` holds those results."""
    done = ", ".join(f"{r.entry.code}={format_value(r.entry, r.new)}" for r in written)
    text = (
        f"{exc}; written and verified before it stopped: {done}" if written else f"{exc}; nothing was written before it"
    )
    if unsure:
        text += f"; {', '.join(e.code for e in unsure)} may or may not have changed (read back with 'param get')"
    exc.args = (text,)
    exc.written = written  # type: ignore[attr-defined]
    return exc


@dataclass(frozen=True)
class SetOutcome:
    results: list[WriteResult]  # the changed entries, written and verified
    stored: list[Entry]  # entries confirmed stored in EEPROM by this command (--save: all requested)
    persisted: bool  # the values survive a power cycle


def set_values(drive: Drive, plan: PreparedSet, save: bool | None) -> SetOutcome:
    """Write a prepared set under the drive's EEPROM rule. save=True stores every requested value, also one RAM
    already holds (RAM and EEPROM may differ, and only a write under the EEPROM setting or the drive's store
    command puts it in EEPROM). A power-cycle parameter that would stay in RAM only is refused before writing."""
    from servotool.ops import journal
    from servotool.ops.eeprom import check_power_cycle, persistence

    check_power_cycle(drive, [e for e, _, _ in plan.changes], save)
    again = plan.unchanged if save and drive.profile.persistence.mode == "switchable" else []
    if not plan.changes and not again and not (save and drive.profile.persistence.mode == "ram"):
        return SetOutcome(
            [], [e for e, _ in plan.unchanged] if save else [], drive.profile.persistence.mode == "immediate"
        )
    results: list[WriteResult] = []
    targets = {e.code: new for e, _old, new in plan.changes}
    before = {e.code: old for e, old, _new in plan.changes}
    # Journaled before the first write: a kill midway is named by the next command, value by value.
    record = journal.operation(drive, "param set", None, targets, before) if targets else nullcontext()
    try:
        with record, persistence(drive, save) as kept:
            results = apply_set(drive, plan)
            for entry, raw in again:  # the same value again, now with the switch on EEPROM
                write_one(drive, entry, raw, raw)
    except ServoError as exc:
        # apply_set names its own writes; the switch read back when the writes ended, or a value written again
        # for EEPROM, fails after them
        raise exc if hasattr(exc, "written") or not results else _naming_written(exc, results, []) from None
    stored = (
        ([r.entry for r in results] + ([e for e, _ in plan.unchanged] if save else [])) if kept["persisted"] else []
    )
    return SetOutcome(results, stored, kept["persisted"])
