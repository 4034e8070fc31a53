"""A fleet inventory: the buses (ports) one host reaches, the machine each belongs to, the units on each, their
profile (or none: found from the drive) and the golden file each drive is compared with or brought to.

    servotool_fleet: 1
    defaults:                      # every bus gets these unless it says otherwise
      profile: sd25
      golden: golden/press.yaml    # a settings file or a snapshot (paths relative to this file)
    buses:
      - machine: press-01
        port: /dev/serial/by-id/usb-FTDI_FT232R_A10K1XYZ-if00-port0
        units: [1, 2, 3]
      - machine: press-02
        name: axes                 # the bus's name in snapshot files (default: from its port)
        port: tcp://10.0.2.15:4001
        baud: 19200
        units: [1, {unit: 2, golden: golden/spindle.yaml}]

A bus takes the connection options of the config file (profile, baud, parity, stopbits, timeout, retries, echo,
turnaround_ms, silence_ms, no_identity_check, boost). One profile per bus: without one it is found from the first
unit's answers, and every other unit is checked against it. A bus may be listed once: two workers on one RS485 line
would interleave their requests.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from servotool.connection import ENV, SIM_PORT, ConnectOptions, check_unit, merge, options_from
from servotool.errors import ServoError, UsageError
from servotool.files import load_yaml
from servotool.link.ports import bus_identity, parse_tcp

FORMAT = 1
BUS_KEYS = ("machine", "name", "port", "units", "golden")
TOP_KEYS = ("servotool_fleet", "defaults", "buses")


@dataclass(frozen=True)
class Target:
    """One drive of the inventory: its unit and the golden file it is compared with (None: none given)."""

    unit: int
    golden: Path | None


@dataclass(frozen=True)
class BusSpec:
    """One bus: the machine it belongs to, its name in files, its connection options and its drives."""

    machine: str
    name: str
    options: ConnectOptions
    targets: tuple[Target, ...]

    @property
    def port(self) -> str:
        return self.options.port or ""

    @property
    def units(self) -> list[int]:
        return [t.unit for t in self.targets]


@dataclass(frozen=True)
class Inventory:
    path: Path
    buses: tuple[BusSpec, ...]

    @property
    def drives(self) -> int:
        return sum(len(b.targets) for b in self.buses)


def load(path: Path) -> Inventory:
    """Read and check an inventory; every problem is one UsageError naming the file and the bus, before any port
    is opened."""
    data = load_yaml(path)
    where = str(path)
    if not isinstance(data, dict) or data.get("servotool_fleet") != FORMAT:
        raise UsageError(f"{where}: not a servotool fleet inventory (it starts with 'servotool_fleet: {FORMAT}')")
    _known(data, TOP_KEYS, where)
    defaults = data.get("defaults") or {}
    if not isinstance(defaults, dict):
        raise UsageError(f"{where}: defaults must be a mapping of option: value")
    _known(defaults, (*ENV, "golden"), f"{where}: defaults")
    buses = data.get("buses")
    if not isinstance(buses, list) or not buses:
        raise UsageError(f"{where}: 'buses' must list one bus at least (machine, port, units)")
    specs = [_bus(item, defaults, path.parent, f"{where}: bus {i + 1}") for i, item in enumerate(buses)]
    _check_distinct(specs, where)
    return Inventory(path, tuple(specs))


def _known(data: dict[str, Any], keys: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(map(str, data)) - set(keys))
    if unknown:
        raise UsageError(f"{where}: unknown key(s) {', '.join(unknown)}")


def _bus(item: Any, defaults: dict[str, Any], folder: Path, where: str) -> BusSpec:
    if not isinstance(item, dict):
        raise UsageError(f"{where}: expected a mapping (machine, port, units)")
    _known(item, (*BUS_KEYS, *ENV), where)
    machine = item.get("machine")
    if not isinstance(machine, str) or not re.fullmatch(r"[A-Za-z0-9_.@-]+", machine) or not machine.strip("."):
        raise UsageError(f"{where}: 'machine' must name the machine the bus belongs to (letters, digits, -_.@)")
    port = item.get("port")
    if not isinstance(port, str) or not port.strip():
        raise UsageError(f"{where} ({machine}): 'port' is missing")
    options = merge(
        options_from({k: v for k, v in item.items() if k in ENV}, where),
        options_from({k: v for k, v in defaults.items() if k in ENV}, f"{where}: defaults"),
    )
    if port != SIM_PORT:
        parse_tcp(port)  # a malformed tcp:// spec is refused here
    golden = _path(item.get("golden", defaults.get("golden")), folder, where)
    units = item.get("units")
    if not isinstance(units, list) or not units:
        raise UsageError(f"{where} ({machine}): 'units' must list the unit ids on the bus")
    targets = []
    for u in units:
        if isinstance(u, dict):
            _known(u, ("unit", "golden"), f"{where} ({machine})")
            unit, own = u.get("unit"), _path(u.get("golden"), folder, where)
        else:
            unit, own = u, None
        if isinstance(unit, bool) or not isinstance(unit, int):
            raise UsageError(f"{where} ({machine}): unit {unit!r} is not a unit id")
        targets.append(Target(check_unit(unit), own or golden))
    if len({t.unit for t in targets}) != len(targets):
        raise UsageError(f"{where} ({machine}): a unit is listed twice")
    name = item.get("name")
    if name is not None and (not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.-]+", name)):
        raise UsageError(f"{where} ({machine}): name must be letters, digits, '-', '_' or '.'")
    return BusSpec(machine, name or _name_of(port), merge(ConnectOptions(port=port), options), tuple(targets))


def _path(value: Any, folder: Path, where: str) -> Path | None:
    if value is None:
        return None
    if not isinstance(value, str) or not value.strip():
        raise UsageError(f"{where}: golden must be a file name")
    path = Path(value).expanduser()
    return path if path.is_absolute() else folder / path


def _name_of(port: str) -> str:
    """A bus's name in file names from its port: ttyUSB0, 10.0.2.15_4001, sim."""
    tcp = parse_tcp(port)
    text = f"{tcp[0]}_{tcp[1]}" if tcp else Path(port).name or port
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_.") or "bus"


def _check_distinct(specs: list[BusSpec], where: str) -> None:
    """Each bus once (one worker per RS485 line), and each (machine, bus name) once (their snapshot files)."""
    seen: dict[str, str] = {}
    names: set[tuple[str, str]] = set()
    for spec in specs:
        key = spec.port if spec.port == SIM_PORT else _identity(spec.port)
        if spec.port == SIM_PORT:
            key = f"sim#{spec.options.profile}"
        if key in seen:
            raise UsageError(
                f"{where}: {spec.port} is listed twice ({seen[key]} and {spec.machine}): list each bus once, with "
                "all its units"
            )
        seen[key] = spec.machine
        if (spec.machine, spec.name) in names:
            raise UsageError(f"{where}: machine {spec.machine} has two buses named {spec.name}: give each a 'name'")
        names.add((spec.machine, spec.name))


def _identity(port: str) -> str:
    try:
        return bus_identity(port)
    except ServoError:
        return port
