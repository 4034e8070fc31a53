"""A faster line for a long exchange (identification, trace, backup, restore) where the drive documents a baud entry
that takes effect at once (profile `serial.boost`: SD25 Po504), and the line put back on every way out.

The drive's baud entry is written in RAM only (the EEPROM rule keeps it out: a power cycle brings back the line
EEPROM holds), the master follows to the new speed and proves it with a short run of reads that must all come
back at the first try; a line that cannot carry it gets the factory speed back at once. Before the entry is
written, its original and both speeds go into the host's journal (ops.journal): a command that finds such a record
(this process killed, the cable pulled) talks to the drive at the factory speed first, then at the raised one, and
puts the entry back (`recover_boost`, before the drive's identity is read). The line is not raised while another
device answers on the bus (it would be left behind at the factory speed) unless asked (`--boost`).
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, replace
from typing import Any

from servotool.drive import Drive
from servotool.errors import DeviceError, ModbusException, ServoError
from servotool.link.master import RtuMaster
from servotool.model.codec import format_value
from servotool.model.profile import Entry, LineSettings
from servotool.ops import eeprom, journal

Notice = Callable[[str], None]

PROBE_IDS = range(1, 9)
"""Ids asked before the line is raised, besides the drives' own: any answer means another device on the bus. The
factory address of every shipped profile is 1, and small machines number their axes from there; a device at a
higher id is not seen (--no-boost on such a bus)."""
TRIAL_READS = 20  # reads at the raised speed that must each come back at the first try
TRIAL_TIMEOUT_S = 0.2


@dataclass(frozen=True)
class BoostFacts:
    """What the line did for the command: its speed meanwhile, the factory speed, and why it was not raised."""

    baud: int
    factory_baud: int
    raised: bool
    why: str = ""  # empty when raised, or when there was nothing to raise (no boost in the profile)

    def as_json(self) -> dict[str, Any]:
        return {"baud": self.baud, "factory_baud": self.factory_baud, "raised": self.raised, "why": self.why or None}


class LineLeftRaised(DeviceError):
    """The line could not be put back: the drive may still listen at the raised speed (the journal keeps it)."""

    exit_code = 1


_RAISED: dict[tuple[str, int, str], tuple[Entry, int]] = {}


def held_originals(drive: Drive) -> dict[str, int]:
    """Entries whose value the raised line holds for its duration (code -> the original raw value): a backup
    records the original, which comes back when the command ends."""
    found = _RAISED.get((drive.port, drive.unit, drive.profile.id))
    return {found[0].code: found[1]} if found else {}


def _key(drive: Drive) -> tuple[str, int, str]:
    return (drive.port, drive.unit, drive.profile.id)


def _plan(drives: list[Drive], choice: bool | None, sole: bool) -> tuple[int | None, str]:
    """(the speed to raise the line to, None for none; why not, in words: empty where the profile has no boost)."""
    profile, link = drives[0].profile, drives[0].link
    boost = profile.boost
    if not boost.available or not isinstance(link, RtuMaster):
        return None, ""
    if choice is False:
        return None, "--no-boost"
    if link.line.baud >= boost.to_baud:
        return None, ""
    if choice is None and not sole and (others := _others_answering(link, [d.unit for d in drives])):
        ids = ", ".join(map(str, others))
        return None, (
            f"unit {ids} also answer{'s' if len(others) == 1 else ''} on this bus and would be left behind at "
            f"{link.line.baud} baud (--boost raises it anyway)"
        )
    return boost.to_baud, ""


def _others_answering(link: RtuMaster, units: list[int]) -> list[int]:
    """The ids of PROBE_IDS besides `units` that answer a one-register read (an exception answer counts)."""
    found = []
    with link.quick(probe_timeout(link.line.baud)):
        for unit in (u for u in PROBE_IDS if u not in units):
            try:
                link.read(unit, 0, 1)
            except ModbusException:
                found.append(unit)
            except DeviceError as exc:
                if exc.fault not in ("silent", ""):
                    found.append(unit)  # garbled or stray: something is there
                elif not exc.fault:
                    raise
                continue
            else:
                found.append(unit)
    return found


def probe_timeout(baud: int) -> float:
    """How long an id is given to answer a one-register read: both frames' wire time (15 characters of 11 bits)
    twice over, and 20 ms for the drive (54 ms at 9600 baud)."""
    return 2 * 15 * 11 / baud + 0.02


@contextmanager
def line_boost(
    drives: list[Drive], choice: bool | None, *, sole: bool = False, notice: Notice | None = None, what: str = ""
) -> Iterator[BoostFacts]:
    """Run the block on a raised line where the profile documents one and nothing speaks against it: choice True
    (--boost) raises it even when another device answers, False (--no-boost) never, None where no other does
    (`sole`: the bus is known to hold only these drives, the embedded simulator). Yields what the line did; the
    line is put back (and proven) on every way out, LineLeftRaised when it cannot be."""
    say = notice or _stderr
    link = drives[0].link
    factory = link.line.baud if isinstance(link, RtuMaster) else drives[0].profile.line.baud
    target, why = _plan(drives, choice, sole)
    if target is None:
        if why and why != "--no-boost":
            say(f"servotool: line not raised: {why}")
        yield BoostFacts(factory, factory, False, why)
        return
    assert isinstance(link, RtuMaster)
    entry = drives[0].profile.entry(drives[0].profile.boost.code)
    with journal.port_lock(drives[0]):
        raised = _raise(link, drives, entry, target, say)
        if raised is None:
            yield BoostFacts(factory, factory, False, f"the line does not carry {target} baud")
            return
        originals, factory_line = raised
        say(
            f"servotool: line raised to {target} baud{f' for {what}' if what else ''} ({entry.code} in RAM only; "
            f"back to {factory} baud when it ends, or at the next power cycle)"
        )
        failing = True
        try:
            yield BoostFacts(target, factory, True)
            failing = False
        finally:
            _put_back(link, drives, entry, originals, factory_line, failing)


def _raise(
    link: RtuMaster, drives: list[Drive], entry: Entry, target: int, say: Notice
) -> tuple[dict[int, int], LineSettings] | None:
    """Write the raised code to every drive (RAM only), follow it and prove it; (originals by unit, the factory
    line) once it holds, None when the drives do not hold their factory code or the line fails the trial (then
    the factory speed is back)."""
    boost = drives[0].profile.boost
    factory_line = link.line
    code = boost.code_of(target)
    assert code is not None
    originals = {d.unit: d.read_entries([entry])[0].raw for d in drives}
    if any(boost.rates.get(raw) != factory_line.baud for raw in originals.values()):
        odd = ", ".join(f"unit {u}: {format_value(entry, r)}" for u, r in originals.items())
        say(
            f"servotool: line not raised: {entry.code} reads {odd}, not the code of the line's {factory_line.baud} baud"
        )
        return None
    for d in drives:
        journal.note_boost(
            d,
            {
                "code": entry.code,
                "original": originals[d.unit],
                "raised": code,
                "factory_baud": factory_line.baud,
                "baud": target,
            },
        )
        _RAISED[_key(d)] = (entry, originals[d.unit])
    raised_line = replace(factory_line, baud=target)
    with ExitStack() as switches:  # the EEPROM switch at RAM (SD25's factory Po505), confirmed at the new speed
        for d in drives:
            switches.enter_context(eeprom.persistence(d, False))
        for d in drives:
            _send(d, entry, code)
        link.set_line(raised_line)
        trouble = _trial(link, drives, entry, code)
        if trouble is not None:
            for d in drives:
                _send(d, entry, originals[d.unit])
            link.set_line(factory_line)
    if trouble is None:
        return originals, factory_line
    say(f"servotool: line not raised: {target} baud failed its trial ({trouble}); back at {factory_line.baud} baud")
    if not _back(drives, entry, originals):
        _put_back(link, drives, entry, originals, factory_line, False)
    for d in drives:
        journal.clear_boost(d)
        _RAISED.pop(_key(d), None)
    return None


def _send(drive: Drive, entry: Entry, raw: int) -> None:
    """One try of the write that changes the drive's speed: its reply may come at either speed or be lost, so it is
    never repeated at this one; what the drive holds is read at the speed the write sets."""
    try:
        drive.write_raw(entry, raw, idempotent=False)
    except ModbusException:
        raise
    except DeviceError as exc:
        if not exc.fault:
            raise


def _trial(link: RtuMaster, drives: list[Drive], entry: Entry, code: int) -> str | None:
    """TRIAL_READS reads of the baud entry from each drive, each answered at the first try with the raised code;
    what failed, or None."""
    before = link.requests
    try:
        with link.quick(TRIAL_TIMEOUT_S):
            for _ in range(TRIAL_READS):
                for d in drives:
                    if (raw := d.read_entries([entry])[0].raw) != code:
                        return f"unit {d.unit} reads {entry.code} = {format_value(entry, raw)}"
    except ServoError as exc:
        return str(exc)
    sent = link.requests - before
    if sent != TRIAL_READS * len(drives):
        return f"{sent - TRIAL_READS * len(drives)} of {TRIAL_READS * len(drives)} reads needed a second try"
    return None


def _back(drives: list[Drive], entry: Entry, originals: dict[int, int]) -> bool:
    """Whether every drive answers at the master's speed now with its original code. A drive that answers here
    with another code (its port kept this speed: a simulator on a serial port, a drive that ignored the change)
    gets the original written at this speed."""
    try:
        for d in drives:
            if d.read_entries([entry])[0].raw != originals[d.unit]:
                with eeprom.persistence(d, False):
                    d.write_verified(entry, originals[d.unit])
        return True
    except ServoError:
        return False


def _put_back(
    link: RtuMaster,
    drives: list[Drive],
    entry: Entry,
    originals: dict[int, int],
    factory_line: LineSettings,
    failing: bool,
) -> None:
    """The original code back (at the raised speed), the master back at the factory speed, proven by a read there;
    tried a few times. The journal record goes once it is proven; otherwise LineLeftRaised (unless another error is
    on its way out: the record stays for the next command). A Ctrl-C meanwhile is raised once the line is back."""
    raised_line = link.line
    interrupt: KeyboardInterrupt | None = None
    for _attempt in range(3):
        try:
            if link.line != factory_line:
                with ExitStack() as switches:
                    for d in drives:
                        switches.enter_context(eeprom.persistence(d, False))
                    for d in drives:
                        _send(d, entry, originals[d.unit])
                    link.set_line(factory_line)
            if _back(drives, entry, originals):
                for d in drives:
                    journal.clear_boost(d)
                    _RAISED.pop(_key(d), None)
                if interrupt is not None:
                    raise interrupt
                return
        except KeyboardInterrupt as exc:
            interrupt = exc
        except ServoError:
            pass
        link.set_line(raised_line)  # not back: try again from the raised speed
    link.set_line(factory_line)
    for d in drives:
        _RAISED.pop(_key(d), None)
    if interrupt is not None:
        raise interrupt
    if not failing:
        raise LineLeftRaised(
            f"the line could not be put back to {factory_line.baud} baud: {entry.code} may still hold "
            f"{raised_line.baud} baud (in RAM only: a power cycle brings back the factory line); the next command "
            "tries both speeds and puts it back"
        )


def recover_boost(drives: list[Drive], notice: Notice | None = None) -> list[str]:
    """Put back a line a dead servotool process left raised (its journal record), before anything else reads the
    drive: at the master's speed first, then at the raised one. Left alone while a live process holds the port
    (it puts the line back itself). Returns the lines given to notice."""
    say = notice or _stderr
    link = drives[0].link
    found = [(d, r) for d in drives if (r := journal.boost_record(d)) is not None]
    if not found or not isinstance(link, RtuMaster):
        return []
    lines: list[str] = []
    with journal.lock_if_free(drives[0]) as free:
        if not free:
            return []
        for d, record in found:
            line = _recover_one(link, d, record)
            if line:
                lines.append(line)
                say(line)
    return lines


def _recover_one(link: RtuMaster, drive: Drive, record: dict[str, Any]) -> str:
    """One drive's raised line put back: the line to tell (empty for a damaged record, which goes)."""
    entry = drive.profile.find(str(record.get("code")))
    original, raised, baud = record.get("original"), record.get("raised"), record.get("baud")
    if (
        entry is None
        or not all(isinstance(v, int) and not isinstance(v, bool) for v in (original, raised, baud))
        or not entry.min <= int(original) <= entry.max  # type: ignore[arg-type]
    ):
        journal.clear_boost(drive)
        return ""
    assert isinstance(original, int) and isinstance(baud, int)
    pid, here = record.get("pid"), link.line
    head = f"servotool: a servotool process (pid {pid}) ended with the line of unit {drive.unit} raised to {baud} baud"
    with link.quick(3 * TRIAL_TIMEOUT_S):
        now = _read_or_none(drive, entry)
    if now is not None:  # it answers at this speed: power-cycled, or put back already
        if now != original:
            drive.write_verified(entry, original)
        journal.clear_boost(drive)
        return f"{head}; it answers at {here.baud} baud again ({entry.code} = {format_value(entry, original)})"
    link.set_line(replace(here, baud=baud))
    try:
        with link.quick(3 * TRIAL_TIMEOUT_S):
            now = _read_or_none(drive, entry)
        if now is not None:
            with eeprom.persistence(drive, False):
                _send(drive, entry, original)
                link.set_line(here)
    finally:
        link.set_line(here)
    if now is not None and _back([drive], entry, {drive.unit: original}):
        journal.clear_boost(drive)
        return f"{head}; put {entry.code} back to {format_value(entry, original)} (was {format_value(entry, now)})"
    return (
        f"{head}: it answers neither at {here.baud} nor at {baud} baud now; power-cycle it to bring back the line "
        f"its EEPROM holds ({entry.code} was raised in RAM only)"
    )


def _read_or_none(drive: Drive, entry: Entry) -> int | None:
    try:
        return drive.read_entries([entry])[0].raw
    except ServoError:
        return None


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)
