"""Behaviour of one simulated drive: answers register requests, runs Fn functions, keeps its state file."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from servotool.model.profile import Entry, Profile
from servotool.sim.registers import ILLEGAL_ADDRESS, ILLEGAL_VALUE, RegisterBank, SimRefusal

FnHandler = Callable[["SimulatedDrive", Entry, int], None]

# The simulated machine's true properties (never readable over Modbus), persisted with the drive's state.
SIM_SETTINGS: dict[str, tuple[type, float | int | str, float, float, str]] = {
    # name: (type, default, min, max, help)
    "load_ratio": (float, 2.0, 0.0, 200.0, "true load inertia / motor inertia"),
    "friction": (float, 0.02, 0.0, 1.0, "Coulomb friction, fraction of rated torque"),
    "viscous": (float, 0.0005, 0.0, 1.0, "viscous friction, fraction of rated torque per rad/s"),
    "load_torque": (float, 0.0, -2.0, 2.0, "constant load (gravity) torque, fraction of rated torque"),
    "noise": (float, 0.002, 0.0, 0.2, "relative measurement noise on speed and torque readings"),
    "seed": (int, 1, 0, 2**31 - 1, "random seed of the measurement noise"),
    "brake": (int, 1, 0, 1, "holding brake (on/off): closed while the servo is off; holds any load_torque"),
    "line_baud": (
        str,
        "factory",
        0,
        0,
        "the line each answer is delayed by (its wire time): factory (the connection's line, the profile's factory "
        "settings unless --baud/--parity/--stopbits say otherwise; SERVOTOOL_SIM_LINE_BAUD may replace it), a baud "
        "rate in that format, or fast (none)",
    ),
    # mechanics outside the rigid model (sim.mechanics); all off by default
    "resonance_hz": (
        float,
        0.0,
        0.0,
        500.0,
        "compliant coupling: the load sits behind a spring, motor-side "
        "resonance at this frequency, Hz (needs load_ratio > 0); 0 = rigid",
    ),
    "resonance_damping": (float, 0.05, 0.001, 1.0, "damping ratio of the coupling's resonance"),
    "backlash_rad": (
        float,
        0.0,
        0.0,
        1.0,
        "backlash: dead zone in the coupling, rad at the motor shaft (needs load_ratio > 0); 0 = none",
    ),
    "arm_gravity": (
        float,
        0.0,
        -2.0,
        2.0,
        "an arm through a gear: gravity torque amplitude, fraction of rated "
        "torque; load torque = arm_gravity * sin(load position / gear + arm_angle)",
    ),
    "arm_angle": (float, 0.0, -180.0, 180.0, "the arm's angle at position 0, degrees from hanging down"),
    "gear": (float, 10.0, 1.0, 1000.0, "gear ratio between motor and arm (motor turns per arm turn)"),
    "cogging": (float, 0.0, 0.0, 0.2, "cogging torque ripple amplitude, fraction of rated torque"),
    "cogging_periods": (int, 6, 1, 200, "cogging ripple periods per motor revolution"),
    "inputs": (
        int,
        0,
        0,
        255,
        "wired digital input levels, bit n = DI n+1 (e.g. 4 = DI3 closed); the drive acts on them unless its "
        "inputs are forced",
    ),
    "di_monitor": (
        int,
        0,
        0,
        1,
        "NOT IN THE MANUAL (forced/terminals): what the input monitor shows while the inputs are forced; the manual's "
        "words read as the forced levels (forced, the default)",
    ),
    "fake_watchdog": (
        int,
        0,
        0,
        1,
        "NOT REAL (on/off): stop host motion after 500 ms of host silence on a drive "
        "whose manual documents no communication timeout; off by default, as on the real drive",
    ),
    "segment_restart": (
        int,
        0,
        0,
        1,
        "for comparison (on/off, default off): a start edge during a running segment restarts segment 1 at once "
        "from where the axis is; off: it is queued until the running segment ends and settles, and a falling "
        "edge brakes the running segment (the stricter reading; neither is in the manual)",
    ),
}


class SimulatedDrive:
    """A drive generated from a profile: registers + Fn functions (+ the plant, when attached)."""

    def __init__(self, profile: Profile, unit: int, state_file: Path | None = None, *, persist: bool = True) -> None:
        self.profile = profile
        self.unit = unit
        self.bank = RegisterBank.open(profile, unit, state_file)
        if not persist:
            self.bank.path = None
        self.handlers: dict[str, FnHandler] = {
            "factory_reset": _factory_reset,
            "soft_reset": _soft_reset,
            "eeprom_save": _eeprom_save,
        }
        self.on_read: list[Callable[[SimulatedDrive], None]] = []
        self.on_param_change: list[Callable[[SimulatedDrive, Entry, int], None]] = []
        self.on_reload: list[Callable[[SimulatedDrive], None]] = []
        self._take_extra()

    def _take_extra(self) -> None:
        self.settings = sim_settings(self.bank.extra.get("settings"))
        self.fault_injection: dict[str, int] = dict(self.bank.extra.get("inject", {}))
        self.missing: list[str] = [c for c in self.bank.extra.get("missing", []) if self.profile.find(c)]
        self._holes = {a for c in self.missing for a in self.profile.entry(c).addresses}

    @contextmanager
    def session(self) -> Iterator[None]:
        """One request or command on the drive: under its state-file lock, with what other processes saved."""
        with self.bank.locked() as reloaded:
            if reloaded:
                self._take_extra()
                for hook in self.on_reload:
                    hook(self)
            yield

    @property
    def line_baud(self) -> str | int:
        """The line this drive's answers are timed by: "factory", "fast" or a baud rate (sim config)."""
        return self.settings["line_baud"]

    def configure(self, **changes: float | int | str) -> None:
        """Change and persist simulated-machine settings (validated)."""
        changes = {k: v for k, v in changes.items() if v is not None}
        if "line_baud" in changes:  # as given now: 0 is fast, as it always meant when given
            from servotool.errors import UsageError

            try:
                changes["line_baud"] = line_choice(changes["line_baud"])
            except ValueError as exc:
                raise UsageError(f"sim setting {exc}") from None
        with self.session():
            merged = {**self.settings, **changes}
            self.settings = sim_settings(merged, strict=True)
            self.bank.extra["settings"] = self.settings
            self.bank.save()

    def role_of(self, entry: Entry) -> str | None:
        for role, code in self.profile.roles.items():
            if code.upper() == entry.code.upper():
                return role
        return None

    def read(self, address: int, count: int) -> list[int]:
        """Registers for a read request; raises SimRefusal for a Modbus exception."""
        with self.session():
            self._check_present(address, count)
            for hook in self.on_read:
                hook(self)
            return self.bank.read(address, count)

    def write(self, address: int, values: list[int]) -> None:
        """Apply a write request atomically: every entry is checked before any is changed."""
        with self.session():
            self._write(address, values)

    def _check_present(self, address: int, count: int) -> None:
        """Exception 02 for a request that touches an entry this drive lacks (set_missing), like an unmapped one."""
        if self._holes and not self._holes.isdisjoint(range(address, address + count)):
            raise SimRefusal(ILLEGAL_ADDRESS, f"address range {address}+{count} reaches an entry this drive lacks")

    def set_missing(self, codes: list[str]) -> list[str]:
        """Make the drive lack these entries (a firmware without addresses its manual lists): every request that
        touches one is answered with exception 02. An empty list restores them all. Returns the codes."""
        entries = [self.profile.entry(c) for c in codes]
        with self.session():
            self.bank.extra["missing"] = [e.code for e in entries]
            if not entries:
                self.bank.extra.pop("missing")
            self.bank.save()
            self._take_extra()
        return self.missing

    def _write(self, address: int, values: list[int]) -> None:
        self._check_present(address, len(values))
        changes = self.bank.decode_write(address, values)
        for entry, _raw in changes:
            if (code := self.fault_injection.get(entry.code.upper())) is not None:
                raise SimRefusal(code or ILLEGAL_VALUE, f"injected fault on {entry.code}")
        changed = False
        for entry, raw in changes:
            if entry.cls == "Fn":
                self._run_function(entry, raw)
                changed = True
            elif entry.cls == "Pn":
                self.bank.apply_parameter(entry, raw)
                for hook in self.on_param_change:
                    hook(self, entry, raw)
                changed = True
            else:
                self.bank.set_live(entry.code, raw)
        if changed:
            self.bank.save()

    def _run_function(self, entry: Entry, raw: int) -> None:
        role = self.role_of(entry)
        handler = self.handlers.get(role or "")
        if handler is None:
            # A function the simulator does not model still answers like a drive that accepted it.
            return
        handler(self, entry, raw)

    def power_cycle(self) -> list[str]:
        """Switch the drive off and on; returns the codes whose pending change took effect."""
        with self.session():
            pending = self.bank.pending_power_cycle()
            self.bank.power_cycle()
            self.bank.save()
            for hook in self.on_reload:
                hook(self)
            return pending

    def inject_fault(self, code: str, exception: int = ILLEGAL_VALUE) -> None:
        """Make writes to one entry fail with a Modbus exception (tests of rollback paths)."""
        entry = self.profile.entry(code)
        with self.session():
            self.fault_injection[entry.code.upper()] = exception
            self.bank.extra["inject"] = self.fault_injection
            self.bank.save()

    def clear_faults(self) -> None:
        with self.session():
            self.fault_injection.clear()
            self.bank.extra.pop("inject", None)
            self.bank.save()


def _factory_reset(drive: SimulatedDrive, entry: Entry, raw: int) -> None:
    if raw == entry.trigger:
        drive.bank.factory_reset()


def _soft_reset(drive: SimulatedDrive, entry: Entry, raw: int) -> None:
    if raw == entry.trigger:
        drive.bank.power_cycle()


def _eeprom_save(drive: SimulatedDrive, entry: Entry, raw: int) -> None:
    if raw == entry.trigger:
        drive.bank.save_eeprom()


LINE_FACTORY, LINE_FAST = "factory", "fast"
LINE_BAUDS = (300, 10_000_000)


def line_choice(value: object) -> str | int:
    """A line to emulate as given (sim config --line-baud, sim serve --line-baud, SERVOTOOL_SIM_LINE_BAUD):
    "factory", "fast" (also "off" and 0, the old word for it) or a baud rate; ValueError otherwise."""
    text = str(value).strip().lower()
    if text in (LINE_FACTORY, LINE_FAST):
        return text
    if text in ("off", "0"):
        return LINE_FAST
    if not text.isascii() or not text.isdigit() or not LINE_BAUDS[0] <= int(text) <= LINE_BAUDS[1]:
        raise ValueError(f"line baud must be factory, fast or {LINE_BAUDS[0]}..{LINE_BAUDS[1]}, not {value!r}")
    return int(text)


def _stored_line(value: object) -> str | int:
    """The stored line setting; a stored 0 is the old default, which every sim config saved: factory now."""
    return LINE_FACTORY if value == 0 else line_choice(value)


def sim_settings(raw: object, *, strict: bool = False) -> dict[str, float | int | str]:
    """Settings with defaults filled in; strict=True raises UsageError for bad values instead of ignoring them."""
    from servotool.errors import UsageError

    given = raw if isinstance(raw, dict) else {}
    out: dict[str, float | int | str] = {}
    for name, (kind, default, lo, hi, _help) in SIM_SETTINGS.items():
        value = given.get(name, default)
        try:
            if name == "line_baud":
                value, ok = _stored_line(value), True
            else:
                value = kind(value)
                ok = lo <= value <= hi
        except (TypeError, ValueError):
            ok = False
        if not ok:
            if strict:
                within = f"{lo}..{hi}" if name != "line_baud" else f"factory, fast or {LINE_BAUDS[0]}..{LINE_BAUDS[1]}"
                raise UsageError(f"sim setting {name}={given.get(name)!r} is outside {within}")
            value = default
        out[name] = value
    if strict and (out["resonance_hz"] or out["backlash_rad"]) and not out["load_ratio"]:
        raise UsageError(
            "sim setting resonance_hz or backlash_rad needs a load behind the coupling: set load_ratio > 0"
        )
    return out
