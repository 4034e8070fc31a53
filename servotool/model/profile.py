"""Profile data types: entries, line settings, limits, persistence, motor, alarms, motion setup items."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from servotool.errors import MissingRole, UnknownName
from servotool.model.lookup import code_key, suggest

if TYPE_CHECKING:
    from servotool.model.alarm_notes import AlarmCauses, AlarmLog
    from servotool.model.terminals import IoMap

CLASSES = ("Pn", "Un", "Sn", "Fn")


TYPES = {"u16": (1, False), "s16": (1, True), "u32": (2, False), "s32": (2, True), "u64": (4, False), "s64": (4, True)}


ACCESS = ("rw", "ro", "wo")


EFFECTS = ("immediate", "servo_off", "power_cycle", "unknown")


FORMATS = ("dec", "hex", "digits", "bits")


WORD_ORDERS = ("low_first", "high_first")


PERSISTENCE = ("immediate", "ram", "switchable")


DEFAULT_ACCESS = {"Pn": "rw", "Un": "ro", "Sn": "ro", "Fn": "wo"}


ALARM_KINDS = (
    "overspeed",
    "overload",
    "following_error",
    "comm_timeout",
    "inertia_id_failed",
    "overtravel",
    "locked_rotor",
    "saturation",
    "other",
)


CONVENTIONS = {"inertia_ratio": ("load_over_motor", "total_over_motor")}


# A ramp time whose reference speed a profile does not describe is read as the time to this speed (or the rated one).
UNDESCRIBED_RAMP_RPM = 1000.0


@dataclass(frozen=True)
class Entry:
    """One register-mapped item of a drive."""

    code: str
    cls: str
    name: str
    address: int
    type: str = "u16"
    word_order: str = "low_first"
    combine: str = "binary"
    digits: int = 5
    scale: float = 1.0
    unit: str = ""
    min: int = 0
    max: int = 0
    default: int | None = None
    access: str = "rw"
    effect: str = "unknown"
    group: str = ""
    description: str = ""
    source: str = ""
    unverified: str = ""
    format: str = "dec"
    fields: tuple[str, ...] = ()
    field_width: int = 4
    field_ranges: dict[str, tuple[int, int]] = field(default_factory=dict)  # upper-case field name -> (lo, hi)
    field_enums: dict[str, dict[int, str]] = field(default_factory=dict)  # upper-case field name -> meanings
    bits: dict[int, str] = field(default_factory=dict)
    enum: dict[int, str] = field(default_factory=dict)
    trigger: int = 1
    copy: bool = True

    @property
    def words(self) -> int:
        """Number of 16-bit registers the entry occupies."""
        return TYPES[self.type][0]

    @property
    def signed(self) -> bool:
        return TYPES[self.type][1]

    @property
    def readable(self) -> bool:
        return self.access in ("rw", "ro")

    @property
    def writable(self) -> bool:
        return self.access in ("rw", "wo")

    @property
    def addresses(self) -> range:
        return range(self.address, self.address + self.words)


@dataclass(frozen=True)
class LineSettings:
    """How bytes travel on the RS485 line; the one line-settings type (a profile's factory settings, the client's
    port, the simulator's serial server)."""

    baud: int = 9600
    parity: str = "N"
    stopbits: int = 1
    bytesize: int = 8

    def describe(self) -> str:
        """'9600 8N1' style."""
        return f"{self.baud} {self.bytesize}{self.parity}{self.stopbits}"


@dataclass(frozen=True)
class LineBoost:
    """Whether and how the drive's own line can be raised for a long exchange (profile `serial.boost`): the baud
    entry, its codes (raw -> baud) and the speed to raise it to; `none` says why a drive has no boost."""

    code: str = ""
    rates: dict[int, int] = field(default_factory=dict)
    to_baud: int = 0
    source: str = ""
    unverified: str = ""
    none: str = ""

    @property
    def available(self) -> bool:
        return bool(self.code) and self.to_baud > 0

    def code_of(self, baud: int) -> int | None:
        """The entry's raw value for a baud rate (None: the drive has no code for it)."""
        return next((raw for raw, b in self.rates.items() if b == baud), None)


@dataclass(frozen=True)
class Limits:
    max_read: int = 125
    max_write: int = 123
    write_multiple: bool = True


@dataclass(frozen=True)
class Persistence:
    mode: str = "immediate"
    switch_code: str = ""
    switch_eeprom: int = 0
    switch_ram: int = 1
    switch_digit: str = ""
    write_limit: int | None = None
    note: str = ""

    def is_switch(self, code: str) -> bool:
        """Whether code is the RAM/EEPROM switch of a switchable drive."""
        return bool(self.switch_code) and code.upper() == self.switch_code.upper()


@dataclass(frozen=True)
class Motor:
    rated_torque_nm: float = 1.27
    rated_speed_rpm: float = 3000.0
    max_speed_rpm: float = 6000.0
    rotor_inertia_kgcm2: float = 0.33
    counts_per_rev: int = 131072
    source: str = ""

    @property
    def jm(self) -> float:
        """Rotor inertia in kg*m^2."""
        return self.rotor_inertia_kgcm2 * 1e-4


@dataclass(frozen=True)
class Alarm:
    """One alarm/fault code the drive reports."""

    code: int
    display: str
    name: str
    clearable: bool = True
    kind: str = "other"
    source: str = ""


@dataclass(frozen=True)
class SetupItem:
    """A setting the drive needs before host motion works (motion_setup): value as users type it."""

    code: str
    value: str
    reason: str
    source: str
    unverified: str = ""


@dataclass(frozen=True)
class DeadManRoute:
    """What stops host motion when the host dies (profile key dead_man): the drive's own communication timeout
    (drive_timeout), bounded relative moves re-armed by each beat (segment), or nothing (none)."""

    route: str
    reason: str
    source: str
    unverified: str = ""
    if_host_dies: str = ""
    start_value: int = 1  # segment: the value OR-ed into role segment_start's servo-on value to start a move
    # The speed role jog_accel's ramp time runs up to (rpm); 0: the motor's rated speed, None: not described (the
    # slower of 1000 rpm and the rated speed is assumed). ramp_source: the manual lines, or why it is inferred.
    ramp_reference_rpm: float | None = None
    ramp_source: str = ""


FORCED_MONITOR = ("forced", "terminals")


@dataclass(frozen=True)
class ForcedInputs:
    """Host motion asserts its trigger by forcing the drive's digital inputs (profile key forced_inputs, SD25
    So-57/So-58): while forcing is on, the `levels` entry replaces every input's level. `monitor` is the input-level
    monitor, and `monitor_shows` what it shows while forcing is on: the forced levels, or still the terminals."""

    switch_code: str
    levels_code: str
    monitor_code: str
    source: str
    digit: str = ""  # the switch's field (digits format) that turns forcing on
    on: int = 1
    off: int = 0
    monitor_shows: str = "forced"
    unverified: str = ""


@dataclass(frozen=True)
class IdentityCheck:
    """One read-only address a drive of this family answers in a known way (or, `absent`, refuses with exception
    02): part of the profile's identity signature."""

    address: int
    words: int = 1
    code: str = ""  # the entry read there; "" for an address this map does not have
    absent: bool = False
    range: tuple[int, int] | None = None  # raw values a drive of this family answers; None: presence only
    sim: int | None = None  # what the simulated drive answers (non-Pn entries)
    source: str = ""
    unverified: str = ""

    @property
    def label(self) -> str:
        return self.code or f"address {self.address} (0x{self.address:04X})"


@dataclass(frozen=True)
class Identity:
    """What identifies a profile's drive: its firmware and model entries and the checks made before any write."""

    checks: tuple[IdentityCheck, ...]
    firmware: str = ""
    model: str = ""


@dataclass
class Profile:
    """A loaded, validated drive profile."""

    id: str
    model: str
    vendor: str
    version: str
    description: str
    source: str
    address_rule: str
    line: LineSettings
    default_unit: int
    limits: Limits
    word_order: str
    persistence: Persistence
    motor: Motor | None
    entries: list[Entry]
    roles: dict[str, str]
    groups: dict[str, str]
    alarms: list[Alarm] = field(default_factory=list)
    conventions: dict[str, str] = field(default_factory=dict)
    motion_setup: list[SetupItem] = field(default_factory=list)
    dead_man: DeadManRoute | None = None
    forced_inputs: ForcedInputs | None = None
    unverified_note: str = ""
    identity: Identity | None = None
    io: IoMap | None = None  # the drive's digital inputs and outputs (model.terminals)
    alarm_causes: AlarmCauses | None = None  # the manual's causes and remedies (model.alarm_notes)
    alarm_log: AlarmLog | None = None  # what the drive records with its past alarms (model.alarm_notes)
    unverified_values: dict[str, str] = field(default_factory=dict)  # CODE -> why its scale/meaning is open
    boost: LineBoost = field(default_factory=LineBoost)
    path: Path | None = None
    _by_code: dict[str, Entry] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        self._by_code = {e.code.upper(): e for e in self.entries}

    def entry(self, code: str) -> Entry:
        """The entry with this vendor code (any of the manual's spellings, see model.lookup) or role name."""
        found = self.find(code)
        if found is None:
            same = self._aliases().get(code_key(code) or "", [])
            raise UnknownName(
                "code",
                code,
                self.id,
                [e.code for e in same] if len(same) > 1 else suggest(code, [e.code for e in self.entries]),
            )
        return found

    def find(self, code: str) -> Entry | None:
        hit = self._by_code.get(code.strip().upper())
        if hit is None and code in self.roles:
            hit = self._by_code.get(self.roles[code].upper())
        if hit is None:
            same = self._aliases().get(code_key(code) or "", [])
            hit = same[0] if len(same) == 1 else None
        return hit

    def _aliases(self) -> dict[str, list[Entry]]:
        """Spelling-free code key -> the entries with it (built on first use; more than one: ambiguous)."""
        index: dict[str, list[Entry]] | None = self.__dict__.get("_alias_index")
        if index is None:
            index = {}
            for e in self.entries:
                if (key := code_key(e.code)) is not None:
                    index.setdefault(key, []).append(e)
            self.__dict__["_alias_index"] = index
        return index

    def role(self, name: str) -> Entry | None:
        """The entry a semantic role maps to, or None when the profile lacks it."""
        code = self.roles.get(name)
        return self._by_code.get(code.upper()) if code else None

    def need_role(self, name: str, feature: str) -> Entry:
        """The entry for a role a feature cannot do without."""
        hit = self.role(name)
        if hit is None:
            raise MissingRole(feature, name, self.id)
        return hit

    def of_class(self, *classes: str) -> list[Entry]:
        return [e for e in self.entries if e.cls in classes]

    def alarm(self, code: int) -> Alarm | None:
        return next((a for a in self.alarms if a.code == code), None)

    def alarm_of_kind(self, kind: str) -> Alarm | None:
        return next((a for a in self.alarms if a.kind == kind), None)

    def ramp_rpm(self) -> float:
        """The speed the drive's ramp time (role jog_accel) runs up to, as the profile reads its manual
        (dead_man.ramp_reference_rpm: SDC's PN29 per 1000 rpm, the simulated DSX7E's Pn513 to the rated speed); where
        the profile does not say, the slower reading: 1000 rpm or the rated speed, whichever is lower."""
        rated = self.motor.rated_speed_rpm if self.motor is not None else 3000.0
        reference = self.dead_man.ramp_reference_rpm if self.dead_man is not None else None
        if reference is None:
            return min(UNDESCRIBED_RAMP_RPM, rated)
        return reference or rated

    def value_unverified(self, entry: Entry) -> str:
        """Why this entry's value (its scale, unit or meaning) is not confirmed by the manual; "" when it is."""
        return self.unverified_values.get(entry.code.upper(), "")

    def load_ratio_from_param(self, eng: float) -> float:
        """J_load/J_motor from the inertia-ratio parameter's engineering value, per the profile's convention."""
        entry = self.need_role("inertia_ratio", "inertia ratio conversion")
        ratio = eng / 100.0 if entry.unit == "%" else float(eng)
        if self.conventions.get("inertia_ratio") == "total_over_motor":
            ratio -= 1.0
        return ratio

    def param_from_load_ratio(self, load_ratio: float) -> float:
        """Engineering value of the inertia-ratio parameter for a J_load/J_motor ratio."""
        entry = self.need_role("inertia_ratio", "inertia ratio conversion")
        ratio = load_ratio + 1.0 if self.conventions.get("inertia_ratio") == "total_over_motor" else load_ratio
        return ratio * 100.0 if entry.unit == "%" else ratio


def can_save(profile: Profile) -> bool:
    """Whether values written over Modbus can be made permanent over Modbus."""
    p = profile.persistence
    return p.mode != "ram" or profile.role("eeprom_save") is not None
