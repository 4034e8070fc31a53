"""The host's journal of what servotool is in the middle of changing on a drive, and the per-port write lock.

Before the EEPROM switch is changed for a batch of writes (SD25 Po505, IS620P H0C-13), its original raw value is
recorded here; a restore records its automatic backup and targets; a motion records the settings it changes for
its duration (JOG speed, ramp, segment displacement, the hold's gains, the drive's protections) with their original
raw values, and a motion that forces the drive's inputs (SD25 So-58) the value that releases them. A record
outlives only a process that died (kill -9, power loss of the PC, a line that stopped answering): the next command
on that drive finds it, puts the settings and the switch back and says what the interrupted operation left.
Records live beside the automatic backups, one file per bus, profile and unit, the bus named as the device resolves
(link.ports.bus_identity: tcp://localhost:P and tcp://127.0.0.1:P are one bus, a serial adapter is known by its
/dev/serial/by-id link), and carry the drive's identity entries: a record left under a serial device a replug
renamed is finished by the next command on the same drive under its new name. Every change of a drive's
persistence and every motion happens under the bus's lock, so a record found by whoever holds the lock belongs to
a process that is gone, and a RAM-only write never runs while another process has the switch on EEPROM.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import DeviceError, ServoError
from servotool.files import FileLock, backup_dir, load_yaml, sweep_temp, write_atomic
from servotool.model.codec import format_value
from servotool.model.identity import identity_entries
from servotool.ops.status import servo_is_on
from servotool.words import count

Notice = Callable[[str], None]
LOCK_WAIT_S = 60.0
LOOP_ROLES = ("position_loop_gain", "speed_loop_gain", "speed_loop_integral", "inertia_ratio", "torque_filter")
STANDSTILL_RPM = 20.0  # a motion's settings are put back only below this speed (a hold jitters a few rpm)


def journal_dir() -> Path:
    return backup_dir() / "journal"


def port_key(port: str) -> str:
    """A file-name-safe key for a bus name (Drive.port): readable, and unique by a short hash of the full name."""
    slug = re.sub(r"[^A-Za-z0-9]+", "_", port).strip("_")[-40:] or "port"
    return f"{slug}-{hashlib.sha256(port.encode()).hexdigest()[:10]}"


def record_path(drive: Drive) -> Path:
    """The drive's record: one per bus (Drive.port, the resolved device), profile and unit, so that a record is
    only ever read by a command that speaks the same drive's language."""
    profile = re.sub(r"[^A-Za-z0-9_.-]+", "_", drive.profile.id)
    return journal_dir() / f"{port_key(drive.port)}-{profile}-unit{drive.unit}.json"


def _stderr(text: str) -> None:
    print(text, file=sys.stderr)


# ----- the per-port lock (reentrant within a process) ------------------------------------------------------------


@dataclass
class _Held:
    lock: FileLock
    depth: int = 0


_LOCKS: dict[str, _Held] = {}


def _lock_of(bus: str) -> _Held:
    """This process's handle on a bus's lock file (one per resolved device, shared by every unit on it)."""
    key = port_key(bus)
    return _LOCKS.setdefault(key, _Held(FileLock(journal_dir() / f"{key}.lock")))


@contextmanager
def port_lock(drive: Drive, notice: Notice | None = None, clock: Clock | None = None) -> Iterator[None]:
    """Hold the drive's port for a batch of writes; the first holder in this process also recovers what a dead
    process left in the journal. Drives without a port name (in-process test links) are not locked."""
    if not drive.port:
        yield
        return
    held = _lock_of(drive.port)
    if held.depth == 0:
        clock = clock or RealClock()
        deadline = clock.now() + LOCK_WAIT_S
        while not held.lock.try_acquire():
            if clock.now() > deadline:
                raise DeviceError(
                    f"another servotool process has been writing to {drive.port} for "
                    f"{LOCK_WAIT_S:.0f} s; try again when it has finished"
                )
            clock.sleep(0.01)
    held.depth += 1
    try:
        if held.depth == 1:
            recover(drive, notice or _stderr)
        yield
    finally:
        held.depth -= 1
        if held.depth == 0:
            held.lock.release()


@contextmanager
def lock_if_free(drive: Drive) -> Iterator[bool]:
    """Hold the drive's port for the block if nobody does (yields True), without the recovery port_lock runs
    (ops.boost puts the line back first: until then the drive may not answer at this speed); False when a live
    holder has it (it will put back what it changed itself)."""
    if not drive.port:
        yield True
        return
    held = _lock_of(drive.port)
    if held.depth:
        yield True
        return
    if not held.lock.try_acquire():
        yield False
        return
    held.depth += 1
    try:
        yield True
    finally:
        held.depth -= 1
        held.lock.release()


# ----- records ---------------------------------------------------------------------------------------------------


def read_record(drive: Drive, path: Path | None = None) -> dict[str, Any] | None:
    """This drive's journal record (or the one at path), None when there is none; a damaged one counts as empty
    (and is replaced)."""
    try:
        data = json.loads((path or record_path(drive)).read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


HEADER = ("pid", "port", "bus", "unit", "profile", "identity")


def _write(drive: Drive, data: dict[str, Any]) -> None:
    path = record_path(drive)
    if not data:
        path.unlink(missing_ok=True)
        return
    head = {
        "pid": os.getpid(),
        "bus": drive.port,
        "port": drive.port,
        "unit": drive.unit,
        "profile": drive.profile.id,
        "identity": drive_identity(drive),
    }
    write_atomic(path, json.dumps({**data, **head}, indent=1))


def _update(drive: Drive, **parts: Any) -> None:
    if not drive.port:
        return
    data = {k: v for k, v in (read_record(drive) or {}).items() if k not in HEADER}
    for k, v in parts.items():
        if v is None:
            data.pop(k, None)
        else:
            data[k] = v
    _write(drive, data)


_IDENTITIES: dict[tuple[str, int, str], dict[str, int]] = {}


def know_identity(drive: Drive, values: dict[str, int]) -> None:
    """The identity entries as the identity check read them (code -> raw), when it read them all: no second read."""
    if {e.code for e in identity_entries(drive.profile)} <= set(values):
        _IDENTITIES[(drive.port, drive.unit, drive.profile.id)] = {
            e.code: values[e.code] for e in identity_entries(drive.profile)
        }


def drive_identity(drive: Drive) -> dict[str, int]:
    """The drive's identity entries (code -> raw: the profile's firmware and model registers), read once a process;
    a record carries them so that one left under a port name that is gone is taken up only by the same drive.
    {} when they cannot be read (such a record is finished only under its own port name)."""
    key = (drive.port, drive.unit, drive.profile.id)
    if key not in _IDENTITIES:
        entries = identity_entries(drive.profile)
        try:
            _IDENTITIES[key] = {r.entry.code: r.raw for r in drive.read_entries(entries, partial=True)}
        except ServoError:
            return {}
    return _IDENTITIES[key]


@contextmanager
def operation(
    drive: Drive,
    op: str,
    auto_backup: Path | None,
    targets: dict[str, int],
    before: dict[str, int] | None = None,
) -> Iterator[None]:
    """Record an operation that writes several values, before its first write: its targets (code -> raw) and
    what they were, as an automatic backup (a restore) or inline (`before`, a param set), so that a kill midway is
    reported by the next command with what was written and what was not, read from the drive. The record goes
    when the block ends, also by an exception (which reaches the user with its own account). The port is held from
    before the record is written: the recovery its first holder runs would take this live record for a dead one's
    (and drop it)."""
    record: dict[str, Any] = {"name": op, "targets": targets, "since": RealClock().wall()}
    if auto_backup is not None:
        record["auto_backup"] = str(auto_backup)
    if before is not None:
        record["before"] = before
    with port_lock(drive):
        _update(drive, op=record)
        try:
            yield
        except BaseException:
            # A failure the caller accounts for itself (RestoreFailed) or an interrupt: the record served its
            # purpose only when the process dies; an exception still reaches the user, so the record goes.
            _update(drive, op=None)
            raise
        _update(drive, op=None)


# ----- recovery --------------------------------------------------------------------------------------------------


def recover(drive: Drive, notice: Notice) -> list[str]:
    """Put right what a dead process left (call with the port lock held): the switch back to its journaled value,
    the motion's settings, and one line on an interrupted operation; also from a record of this drive left under
    another name of its bus (an older spelling, or a serial device that a replug renamed). Returns the lines given
    to notice."""
    lines: list[str] = []
    keep: dict[str, Any] = {}
    own = read_record(drive)
    if own is not None:
        lines += _recover_record(drive, own, keep)
    adopt, notes = _elsewhere(drive)
    lines += notes
    for path, record, line in adopt:
        if line:
            lines.append(line)
        lines += _recover_record(drive, record, keep)
        path.unlink(missing_ok=True)
    for line in lines:
        notice(line)
    if own is not None or adopt:
        _write(drive, keep)
    return lines


def _recover_record(drive: Drive, record: dict[str, Any], keep: dict[str, Any]) -> list[str]:
    """The lines of one record's recovery; what must wait (loop gains while the motor turns) goes into keep."""
    lines: list[str] = []
    pid = record.get("pid")
    forcing = record.get("forcing")
    if isinstance(forcing, dict):  # first, moving or not: it is what stops a forced JOG
        lines.append(_release_forcing(drive, forcing, pid))
    if isinstance(record.get("boost"), dict):  # the line's speed: put back by ops.boost before the drive is read
        keep["boost"] = record["boost"]
    if record.get("settings") or record.get("servo"):  # before the switch: written back in RAM, as changed
        line, left = _end_motion(drive, record, pid)
        lines.append(line)
        keep.update(left)
    switch = record.get("switch")
    if isinstance(switch, dict):
        lines.append(_put_switch_back(drive, switch, pid))
    op = record.get("op")
    if isinstance(op, dict):
        lines.append(_interrupted(drive, op, pid))
    return lines


def _elsewhere(drive: Drive) -> tuple[list[tuple[Path, dict[str, Any], str]], list[str]]:
    """Records of this drive kept under another file: (those to finish here, with the line that says why; lines
    naming records of this bus and unit that another profile must finish). A record is this drive's when its
    profile and unit match and its bus is this one under an older name, or a serial device that is gone (a
    replug named the adapter anew) whose lock nobody holds, read by a drive of the same identity."""
    if not drive.port:
        return [], []
    own = record_path(drive)
    try:
        names = sorted(e.name for e in os.scandir(journal_dir()) if e.name.endswith(".json"))
    except OSError:
        return [], []
    adopt: list[tuple[Path, dict[str, Any], str]] = []
    notes: list[str] = []
    for name in names:
        path = journal_dir() / name
        record = read_record(drive, path) if path != own else None
        if not record or not isinstance(record.get("port"), str):
            continue
        bus = _bus_of(record)
        if record.get("unit") != drive.unit:
            continue
        if record.get("profile") != drive.profile.id:
            if bus == drive.port and not bus.startswith("sim:"):
                notes.append(
                    f"servotool: a servotool process (pid {record.get('pid')}) using profile {record.get('profile')} "
                    f"ended with unit {drive.unit} of this port changed: a command with --profile "
                    f"{record.get('profile')} puts it right ({path})"
                )
            continue
        if bus == drive.port:
            adopt.append((path, record, ""))
        elif _gone(bus) and _same_drive(drive, record) and _free(bus):
            adopt.append(
                (
                    path,
                    record,
                    f"servotool: {drive.profile.model} unit {drive.unit} was left changed through {bus}, which is "
                    f"no longer there (the adapter replugged as {drive.port}?): finishing it here",
                )
            )
    return adopt, notes


def _bus_of(record: dict[str, Any]) -> str:
    """The bus a record was written for: its 'bus', or (records of servotool before it resolved port names)
    its port spelling resolved now."""
    from servotool.link.ports import bus_identity

    if isinstance(record.get("bus"), str):
        return str(record["bus"])
    port = str(record["port"])
    if port.startswith("sim:"):
        return f"{port}#{record.get('profile')}"
    try:
        return bus_identity(port)
    except ServoError:
        return port


def _gone(bus: str) -> bool:
    """Whether the serial device a record names is no longer attached, as after a replug that named the adapter
    anew. A tcp:// or simulated bus never is: its records are finished only under its own name; nor is a
    /dev/serial/by-id name, which names the adapter itself (its USB serial number) and comes back with it."""
    from servotool.link.ports import SERIAL_BY_ID

    if bus.startswith(("tcp://", "sim:", f"{SERIAL_BY_ID}/")):
        return False
    if re.fullmatch(r"COM\d+", bus):
        from serial.tools.list_ports import comports

        return bus not in {p.device.upper() for p in comports()}
    return not os.path.exists(bus)


def _same_drive(drive: Drive, record: dict[str, Any]) -> bool:
    """The record names this drive's identity (its firmware and model entries as read now); a profile without
    identity entries matches on profile and unit alone."""
    recorded = record.get("identity")
    if not isinstance(recorded, dict) or (not recorded and identity_entries(drive.profile)):
        return False
    return recorded == drive_identity(drive)


def _free(bus: str) -> bool:
    """Nobody holds the bus's lock (its holder would be at work on the record)."""
    held = _lock_of(bus)
    if held.depth or not held.lock.try_acquire():
        return False
    held.lock.release()
    return True


def _put_switch_back(drive: Drive, switch: dict[str, Any], pid: object) -> str:
    valid = _valid_settings(drive, {str(switch.get("code")): switch.get("original")})
    if not valid:
        return f"servotool: ignored a damaged journal record for unit {drive.unit} ({record_path(drive)})"
    [(code, original)] = valid.items()
    entry = drive.profile.entry(code)
    now = drive.read_entries([entry])[0].raw
    if now == original:
        return (
            f"servotool: a servotool process (pid {pid}) ended while changing {entry.code}; it is "
            f"{format_value(entry, now)} as before"
        )
    drive.write_verified(entry, original)
    return (
        f"servotool: put {entry.code} back to {format_value(entry, original)} (was "
        f"{format_value(entry, now)}): a servotool process (pid {pid}) ended with it changed"
    )


def _release_forcing(drive: Drive, forcing: dict[str, Any], pid: object) -> str:
    """Release the inputs a dead process's motion forced (every input follows its terminal again: a forced JOG
    trigger drops), and put the forced value back."""
    valid = _valid_settings(
        drive,
        {str(forcing.get("switch")): forcing.get("released"), str(forcing.get("levels")): forcing.get("original")},
    )
    if valid is None or len(valid) != 2:
        return f"servotool: ignored a damaged journal record for unit {drive.unit} ({record_path(drive)})"
    (switch, released), (levels, original) = [(drive.profile.entry(c), raw) for c, raw in valid.items()]
    drive.write_verified(switch, released)
    if drive.read_entries([levels])[0].raw != original:
        drive.write_verified(levels, original)
    return (
        f"servotool: released the drive's forced inputs ({switch.code} = {format_value(switch, released)}): a "
        f"servotool process (pid {pid}) ended during a motion with them forced; its inputs follow their terminals "
        "again"
    )


def _end_motion(drive: Drive, record: dict[str, Any], pid: object) -> tuple[str, dict[str, Any]]:
    """What a dead process's motion left, put back once the motor stands: the servo off where the motion switched
    it on, and the settings it changed; a loop gain (how the servo holds the axis) only with the servo off.
    (the line to tell, the record's part still pending)."""
    settings = record.get("settings") or {}
    originals = _valid_settings(drive, settings) if isinstance(settings, dict) else None
    servo = drive.profile.find(str(record.get("servo"))) if record.get("servo") else None
    if originals is None:
        return f"servotool: ignored a damaged journal record for unit {drive.unit} ({record_path(drive)})", {}
    found = [drive.profile.entry(code) for code in originals]
    changed = [
        (e, originals[e.code], r.raw)
        for e, r in zip(found, drive.read_entries(found), strict=True)
        if r.raw != originals[e.code]
    ]
    head = f"servotool: a servotool process (pid {pid}) ended during a motion"
    if _moving(drive):
        return (
            f"{head} and the motor still turns: the servo and {len(changed)} changed setting(s) are left "
            "until a command finds it standing"
        ), {k: v for k, v in record.items() if k in ("settings", "servo")}
    done: list[str] = []
    if servo is not None:
        drive.write_raw(servo, 0)
        done.append("switched the servo off")
    loop = (
        {e.code for r in LOOP_ROLES if (e := drive.profile.role(r)) is not None}
        if servo_is_on(drive) is not False
        else set()
    )
    for entry, raw, was in changed:
        if entry.code not in loop:
            drive.write_verified(entry, raw)
            done.append(f"put {entry.code} to {format_value(entry, raw)} (was {format_value(entry, was)})")
    pending = {e.code: raw for e, raw, _was in changed if e.code in loop}
    line = f"{head}; " + ("; ".join(done) if done else "its settings are as before")
    if pending:
        line += (
            f"; {', '.join(pending)} (loop gains) go back when the servo is off: the next jog or tune "
            "puts them back as it ends"
        )
    return line, ({"settings": pending} if pending else {})


def _valid_settings(drive: Drive, settings: dict[str, Any]) -> dict[str, int] | None:
    """code -> original raw, each an entry of this profile in its range; None when any is not."""
    out: dict[str, int] = {}
    for code, raw in settings.items():
        e = drive.profile.find(str(code))
        if e is None or not isinstance(raw, int) or isinstance(raw, bool) or not e.min <= raw <= e.max:
            return None
        out[e.code] = raw
    return out


def pending_settings(drive: Drive) -> dict[str, int]:
    """Originals (code -> raw) a dead process's motion left to be put back later (loop gains while the servo was
    on): a motion starting now puts them back as it ends, with its own settings."""
    record = read_record(drive) if drive.port else None
    settings = record.get("settings") if record else None
    return (_valid_settings(drive, settings) or {}) if isinstance(settings, dict) else {}


def _moving(drive: Drive) -> bool:
    speed = drive.profile.role("speed_feedback")
    return speed is not None and speed.readable and abs(float(drive.read_entries([speed])[0].eng)) > STANDSTILL_RPM


def _interrupted(drive: Drive, op: dict[str, Any], pid: object) -> str:
    """The line on an operation a dead process left midway: what it wrote and what not, read from the drive."""
    targets = op.get("targets") if isinstance(op.get("targets"), dict) else {}
    if isinstance(op.get("before"), dict):
        return _interrupted_set(drive, op, targets, op["before"], pid)
    auto = Path(str(op.get("auto_backup")))
    try:  # the values section of the backup this process wrote itself (ops.backup checks a user's file)
        data = load_yaml(auto)
        before = {str(c): v for c, v in data["values"].items() if isinstance(v, int)}
    except (ServoError, TypeError, KeyError, AttributeError) as exc:
        return (
            f"servotool: a {op.get('name')} (pid {pid}) was interrupted and its automatic backup {auto} is "
            f"unusable ({exc})"
        )
    entries = [e for e in (drive.profile.find(str(c)) for c in targets) if e is not None and e.readable]
    now = {r.entry.code: r.raw for r in drive.read_entries(entries)} if entries else {}
    written = [c for c, raw in now.items() if raw == targets.get(c) and before.get(c) != raw]
    differ = [c for c, raw in now.items() if before.get(c) is not None and raw != before[c]]
    if not differ:
        return (
            f"servotool: a {op.get('name')} (pid {pid}) was interrupted before changing anything: "
            f"read back, the drive equals the automatic backup {auto}"
        )
    return (
        f"servotool: a {op.get('name')} (pid {pid}) was interrupted after writing {len(written)} of "
        f"{count(len(targets), 'entry')}; read back, the drive differs from the "
        f"automatic backup {auto} in {len(differ)} ({', '.join(differ[:6])}{' ...' if len(differ) > 6 else ''}): "
        f"run it again to finish, or 'servotool param restore {auto}' to go back"
    )


def _interrupted_set(
    drive: Drive, op: dict[str, Any], targets: dict[str, Any], before: dict[str, Any], pid: object
) -> str:
    """A killed param set: each value as read now, against what it was and what the command was writing."""
    head = f"servotool: a {op.get('name')} (pid {pid}) was interrupted"
    wanted, was = _valid_settings(drive, targets), _valid_settings(drive, before)
    if wanted is None or was is None:
        return f"servotool: ignored a damaged journal record for unit {drive.unit} ({record_path(drive)})"
    entries = [drive.profile.entry(c) for c in wanted]
    now = {r.entry.code: r.raw for r in drive.read_entries([e for e in entries if e.readable])}
    written, untouched, other = [], [], []
    for e in entries:
        value = now.get(e.code)
        if value is None:
            other.append(f"{e.code} (write-only: unknown)")
        elif value == wanted[e.code]:
            written.append(f"{e.code} = {format_value(e, value)} (was {format_value(e, was.get(e.code, value))})")
        elif value == was.get(e.code):
            untouched.append(f"{e.code} (still {format_value(e, value)})")
        else:
            other.append(f"{e.code} reads {format_value(e, value)}, neither the old nor the new value")
    if not written and not other:
        return f"{head} before changing anything: {', '.join(untouched)}"
    parts = [f"it wrote {', '.join(written)}" if written else "it wrote none of its values"]
    if untouched:
        parts.append(f"not written: {', '.join(untouched)}")
    if other:
        parts.append("; ".join(other))
    return f"{head}: {'; '.join(parts)}; run it again to finish"


def recover_at_start(drive: Drive, notice: Notice, extra_folders: tuple[Path, ...] = ()) -> None:
    """At the start of a command: sweep temporary files a killed process left (here and in extra_folders, e.g. the
    simulator's), and recover this drive's journal (its own record, or one left under another name of its bus)
    when no live process holds its port (a holder is still at work and will put things back itself)."""
    for folder in (backup_dir(), journal_dir(), *extra_folders):
        sweep_temp(folder)
    if not drive.port:
        return
    try:
        records = any(e.name.endswith(".json") for e in os.scandir(journal_dir()))
    except OSError:
        return
    if not records:
        return
    held = _lock_of(drive.port)
    if held.depth or not held.lock.try_acquire():
        return
    try:
        recover(drive, notice)
    finally:
        held.lock.release()


def note_switch(drive: Drive, code: str, original: int) -> None:
    """Record the switch's original raw value before it is changed."""
    _update(drive, switch={"code": code, "original": original, "since": RealClock().wall()})


def clear_switch(drive: Drive) -> None:
    """The switch is confirmed back: the record goes."""
    _update(drive, switch=None)


def note_boost(drive: Drive, boost: dict[str, Any]) -> None:
    """Record a raised line (the baud entry's original and raised raw values, both speeds) before it is raised:
    the next command finds the drive at either speed and puts it back (ops.boost.recover_boost)."""
    _update(drive, boost={**boost, "since": RealClock().wall()})


def clear_boost(drive: Drive) -> None:
    """The line is confirmed back at its factory speed: the record goes."""
    _update(drive, boost=None)


def boost_record(drive: Drive) -> dict[str, Any] | None:
    """The raised line this drive's record holds (None: none), with the pid of the process that raised it."""
    record = read_record(drive) if drive.port else None
    boost = record.get("boost") if record else None
    return {**boost, "pid": record.get("pid")} if isinstance(boost, dict) and record else None


def note_settings(drive: Drive, originals: dict[str, int]) -> None:
    """Record the original raw values (code -> raw) of settings a motion changes until it ends (added to those
    recorded already, whose originals stay); call again whenever one is added."""
    if not drive.port:
        return
    record = read_record(drive) or {}
    before = record.get("settings") if isinstance(record.get("settings"), dict) else {}
    _update(drive, settings={**originals, **before} or None)


def note_servo(drive: Drive, code: str) -> None:
    """A motion may switch the servo on through this entry: a dead process's is switched off at standstill."""
    _update(drive, servo=code)


def note_forcing(drive: Drive, switch: str, released: int, levels: str, original: int) -> None:
    """Before a motion forces the drive's inputs: the switch's value that releases them and the forced value's
    original, for the next command to release them first should this process die."""
    _update(drive, forcing={"switch": switch, "released": released, "levels": levels, "original": original})


def clear_forcing(drive: Drive) -> None:
    """The inputs are released: the record goes."""
    _update(drive, forcing=None)


def clear_motion(drive: Drive, *, servo_off: bool) -> None:
    """The motion's settings are confirmed back (and, with servo_off, its servo off): their record goes."""
    _update(drive, settings=None, **({"servo": None} if servo_off else {}))
