"""Register bank of a simulated drive: every entry's value, access/range checks, EEPROM vs RAM, state file.

Three layers model a real drive's memory: `eeprom` survives power cycles, `ram` is what reads return (the
drive stays powered between CLI invocations, so RAM is kept in the state file too), and `effective` is what
the control loops use; a power-cycle parameter changes `ram` at once but `effective` only after a power cycle.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.errors import DeviceError
from servotool.files import FileLock, sim_state_dir, write_atomic
from servotool.model.codec import raw_to_words, words_to_raw
from servotool.model.profile import Entry, Profile

ILLEGAL_FUNCTION = 1
ILLEGAL_ADDRESS = 2
ILLEGAL_VALUE = 3
DEVICE_FAILURE = 4
MACHINE_STATE_KEY = "machine"  # extra[...]: the firmware's and plant's running state, kept while the drive is on


class SimRefusal(Exception):
    """A request the simulated drive answers with a Modbus exception."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code


def state_path(profile_id: str, unit: int) -> Path:
    """The state file of one simulated drive, in files.sim_state_dir()."""
    return sim_state_dir() / f"{profile_id}-unit{unit}.json"


@dataclass
class RegisterBank:
    """Values of one simulated drive's entries, addressed like the real drive."""

    profile: Profile
    unit: int
    eeprom: dict[str, int] = field(default_factory=dict)
    ram: dict[str, int] = field(default_factory=dict)
    effective: dict[str, int] = field(default_factory=dict)
    live: dict[str, int] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    eeprom_writes: int = 0
    path: Path | None = None
    _by_address: dict[int, Entry] = field(default_factory=dict, repr=False)
    _stamp: tuple[int, int, int] | None = field(default=None, repr=False)  # the state file as last read/written
    _held: bool = field(default=False, repr=False)
    _dirty: bool = field(default=False, repr=False)
    _file_lock: FileLock | None = field(default=None, repr=False)
    before_write: list[Callable[[], None]] = field(default_factory=list, repr=False)  # e.g. store the plant state

    def __post_init__(self) -> None:
        for e in self.profile.entries:
            for a in e.addresses:
                self._by_address[a] = e
        defaults = {
            e.code: e.default if e.default is not None else max(e.min, min(0, e.max))
            for e in self.profile.entries
            if e.cls == "Pn"
        }
        for layer in (self.eeprom, self.ram, self.effective):
            for code, value in defaults.items():
                layer.setdefault(code, value)
        if self.profile.identity:  # what the real drive answers for its version and type codes
            for check in self.profile.identity.checks:
                if check.code and check.sim is not None:
                    self.live.setdefault(check.code, check.sim)

    # ----- persistence -------------------------------------------------------------------------------------
    # The state file is the drive: every process that serves or configures it (sim serve, --port sim, sim config)
    # changes it under a file lock after reloading what the others saved, so no process undoes another's write.

    @classmethod
    def open(cls, profile: Profile, unit: int, path: Path | None = None) -> RegisterBank:
        """Load the drive's state file, or start from factory defaults when there is none."""
        bank = cls(profile, unit, path=path or state_path(profile.id, unit))
        bank.reload()
        return bank

    def _lock(self) -> FileLock:
        assert self.path is not None
        if self._file_lock is None or self._file_lock.path.parent != self.path.parent:
            self._file_lock = FileLock(self.path.with_name(self.path.name + ".lock"))
        return self._file_lock

    def reload(self) -> bool:
        """Take over the state file when another process changed it since; True when anything was (re)loaded."""
        if self.path is None:
            return False
        try:
            st = os.stat(self.path)
            if (st.st_ino, st.st_mtime_ns, st.st_size) == self._stamp:
                return False
            with self.path.open("rb") as fh:
                st = os.fstat(fh.fileno())
                stamp = (st.st_ino, st.st_mtime_ns, st.st_size)
                text = fh.read().decode("utf-8")
        except FileNotFoundError:
            if self._stamp is None:
                return False
            self._stamp = None  # removed (sim reset --factory): factory state
            self._load({})
            return True
        except (OSError, UnicodeDecodeError) as exc:
            raise self._corrupt(str(exc)) from None
        try:
            data = json.loads(text)
        except ValueError as exc:
            raise self._corrupt(f"not JSON ({exc})") from None
        self._load(data)
        self._stamp = stamp
        return True

    def _corrupt(self, why: str) -> DeviceError:
        return DeviceError(
            f"simulated drive state file {self.path} is unreadable: {why}; move it away or run "
            f"'servotool sim reset --factory --profile {self.profile.id} --unit {self.unit}'"
        )

    def _load(self, data: Any) -> None:
        if not isinstance(data, dict):
            raise self._corrupt("not a mapping")
        if data and data.get("profile") != self.profile.id:
            raise self._corrupt(f"it belongs to profile {data.get('profile')!r}, not {self.profile.id!r}")
        layers = {name: data.get(name) or {} for name in ("eeprom", "ram", "effective")}
        extra, writes = data.get("extra") or {}, data.get("eeprom_writes", 0)
        if (
            not all(isinstance(v, dict) for v in layers.values())
            or not isinstance(extra, dict)
            or not isinstance(writes, int)
        ):
            raise self._corrupt("unexpected layout")
        fresh = RegisterBank(self.profile, self.unit)
        for name, stored in layers.items():
            layer = getattr(fresh, name)
            for code, value in stored.items():
                entry = self.profile.find(code)
                # Values a newer profile no longer allows fall back to the default instead of failing the drive.
                if code in layer and entry and isinstance(value, int) and entry.min <= value <= entry.max:
                    layer[code] = value
            setattr(self, name, layer)
        self.extra = extra
        self.eeprom_writes = writes

    @contextmanager
    def locked(self) -> Iterator[bool]:
        """Hold the drive's lock: reload what other processes saved (yields whether anything was), save at the end."""
        if self.path is None or self._held:
            yield False
            return
        with self._lock().held():
            self._held, self._dirty = True, False
            try:
                yield self.reload()
            finally:
                self._held = False
                if self._dirty:
                    self._write()

    def save(self) -> None:
        """Persist the state (at the end of the current locked() block, or now under the lock)."""
        if self.path is None:
            return
        if self._held:
            self._dirty = True
            return
        with self._lock().held():
            self._write()

    def _write(self) -> None:
        """Write the state file atomically, so a killed process never leaves half a file."""
        assert self.path is not None
        for hook in self.before_write:
            hook()
        data = {
            "profile": self.profile.id,
            "version": self.profile.version,
            "unit": self.unit,
            "eeprom": self.eeprom,
            "ram": self.ram,
            "effective": self.effective,
            "eeprom_writes": self.eeprom_writes,
            "extra": self.extra,
        }
        # Not fsync'ed: it is rewritten after every change, and a drive's RAM does not survive a crash either.
        st = write_atomic(self.path, json.dumps(data, indent=1, sort_keys=True), durable=False)
        self._stamp = (st.st_ino, st.st_mtime_ns, st.st_size)
        self._dirty = False

    def power_cycle(self) -> None:
        """What a real power cycle does: RAM reloads from EEPROM and everything takes effect; the running machine's
        state (latched alarm, servo state, position counter, I^2t) starts afresh. The alarm history stays."""
        self.ram = dict(self.eeprom)
        self.effective = dict(self.eeprom)
        self.extra.pop(MACHINE_STATE_KEY, None)

    def factory_reset(self) -> None:
        """Factory defaults into EEPROM and RAM; power-cycle parameters wait for the next power cycle."""
        for e in self.profile.of_class("Pn"):
            if e.default is None:
                continue
            self.eeprom[e.code] = e.default
            self.ram[e.code] = e.default
            if e.effect != "power_cycle":
                self.effective[e.code] = e.default
        self.eeprom_writes += 1

    def save_eeprom(self) -> None:
        """An explicit 'store parameters' function: RAM into EEPROM."""
        self.eeprom = dict(self.ram)
        self.eeprom_writes += 1

    # ----- values ------------------------------------------------------------------------------------------
    def value(self, code: str) -> int:
        """Current raw value as a read would return it."""
        entry = self.profile.entry(code)
        if entry.cls == "Pn":
            return self.ram[entry.code]
        return self.live.get(entry.code, 0)

    def effective_value(self, code: str) -> int:
        entry = self.profile.entry(code)
        return self.effective[entry.code] if entry.cls == "Pn" else self.live.get(entry.code, 0)

    def set_live(self, code: str, raw: int, *, wrap: bool = False) -> None:
        """Set a monitor/status value: clamped to the entry's range, or wrapped into it like a multi-turn counter."""
        entry = self.profile.entry(code)
        if wrap:
            self.live[entry.code] = (int(raw) - entry.min) % (entry.max - entry.min + 1) + entry.min
        else:
            self.live[entry.code] = max(entry.min, min(entry.max, int(raw)))

    def persists_writes(self) -> bool:
        """Whether a Modbus write of a parameter goes to EEPROM right now (per the profile's rule)."""
        p = self.profile.persistence
        if p.mode == "immediate":
            return True
        if p.mode == "ram":
            return False
        switch = self.profile.entry(p.switch_code)
        raw = self.ram[switch.code]
        if p.switch_digit and switch.format == "digits":
            idx = [f.upper() for f in switch.fields].index(p.switch_digit.upper())
            raw = (raw >> (switch.field_width * idx)) & ((1 << switch.field_width) - 1)
        return raw == p.switch_eeprom

    # ----- register access -----------------------------------------------------------------------------------
    def entries_in(self, address: int, count: int) -> list[Entry]:
        """Entries touched by a request; SimRefusal(02) when any address is unmapped."""
        out: list[Entry] = []
        for a in range(address, address + count):
            entry = self._by_address.get(a)
            if entry is None:
                raise SimRefusal(ILLEGAL_ADDRESS, f"address {a} is not mapped")
            if not out or out[-1] is not entry:
                out.append(entry)
        return out

    def read(self, address: int, count: int) -> list[int]:
        if count < 1 or count > self.profile.limits.max_read:
            raise SimRefusal(ILLEGAL_VALUE, f"count {count} exceeds the drive's limit {self.profile.limits.max_read}")
        words: dict[int, int] = {}
        for entry in self.entries_in(address, count):
            raw = self.value(entry.code) if entry.readable else 0
            words.update(zip(entry.addresses, raw_to_words(entry, raw), strict=True))
        return [words[a] for a in range(address, address + count)]

    def decode_write(self, address: int, values: list[int]) -> list[tuple[Entry, int]]:
        """Validate a write and return (entry, new raw value) pairs without applying anything."""
        if len(values) > self.profile.limits.max_write:
            raise SimRefusal(ILLEGAL_VALUE, f"{len(values)} registers exceed the write limit")
        incoming = dict(zip(range(address, address + len(values)), values, strict=True))
        changes: list[tuple[Entry, int]] = []
        for entry in self.entries_in(address, len(values)):
            if not entry.writable:
                raise SimRefusal(ILLEGAL_ADDRESS, f"{entry.code} is read-only")
            current = raw_to_words(entry, self.value(entry.code) if entry.cls == "Pn" else 0)
            words = [incoming.get(a, current[i]) for i, a in enumerate(entry.addresses)]
            raw = words_to_raw(entry, words)
            if not entry.min <= raw <= entry.max:
                raise SimRefusal(ILLEGAL_VALUE, f"{entry.code}={raw} outside {entry.min}..{entry.max}")
            changes.append((entry, raw))
        return changes

    def apply_parameter(self, entry: Entry, raw: int) -> None:
        """Store an accepted parameter write in RAM (and EEPROM when the drive persists writes)."""
        # The EEPROM switch itself is modelled as always stored (the manuals do not say); other writes follow it. A
        # forcing switch is never stored (SD25 So-58: 'not written to EEPROM', cleared at power-up, L5260-5287).
        forced = self.profile.forced_inputs
        persist = (self.persists_writes() or self.profile.persistence.is_switch(entry.code)) and not (
            forced is not None and entry.code.upper() == forced.switch_code.upper()
        )
        self.ram[entry.code] = raw
        if entry.effect != "power_cycle":
            self.effective[entry.code] = raw
        if persist and self.eeprom.get(entry.code) != raw:
            self.eeprom[entry.code] = raw
            self.eeprom_writes += 1

    def pending_power_cycle(self) -> list[str]:
        """Codes whose RAM value differs from the value in effect."""
        return [c for c, v in self.ram.items() if self.effective.get(c) != v]
