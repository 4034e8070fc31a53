"""Connection options, layered CLI > environment > config file > profile defaults, resolved and checked."""

from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, fields
from typing import Any

from servotool.errors import UsageError
from servotool.files import config_file, load_yaml
from servotool.link.ports import LinkSettings, parse_tcp
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings, Profile

SIM_PORT = "sim"


SIM_DEFAULT_PROFILE = "dsx7e"


ECHO = {"auto": None, "on": True, "off": False}
FLOATS = ("timeout", "turnaround_ms", "silence_ms", "travel", "heartbeat_timeout_ms")
HEARTBEAT_LINES = ("dtr", "rts")
HEARTBEAT_TIMEOUT_MS = 1000.0  # the relay's time when none is given (README: the wiring recipe)


PARITIES = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}


@dataclass(frozen=True)
class ConnectOptions:
    """What the user asked for; None means 'not given here'."""

    port: str | None = None
    baud: int | None = None
    parity: str | None = None
    stopbits: int | None = None
    unit: int | None = None
    timeout: float | None = None
    retries: int | None = None
    profile: str | None = None
    travel: float | None = None  # soft travel limit of host motion, rev either way (jog --travel)
    no_identity_check: bool | None = None
    echo: str | None = None  # auto, on or off
    turnaround_ms: float | None = None
    silence_ms: float | None = None
    heartbeat: str | None = None  # dtr or rts: a control line toggled at each keep-alive beat (a watchdog relay)
    heartbeat_timeout_ms: float | None = None  # the relay's time
    boost: bool | None = None  # raise the line where the profile allows (True: even beside other devices)


ENV = {f.name: f"SERVOTOOL_{f.name.upper()}" for f in fields(ConnectOptions)}


def _convert(name: str, value: Any, where: str) -> Any:
    if value is None or value == "":
        return None
    if name in ("no_identity_check", "boost"):
        return _flag(value, where)
    if name == "echo" and isinstance(value, bool):  # YAML reads a bare on/off as a boolean
        return "on" if value else "off"
    if name not in ("baud", "stopbits", "unit", "retries", *FLOATS):
        return str(value)
    kind = "a number" if name in FLOATS else "a whole number"
    try:
        number = _number(value, whole=name not in FLOATS)
    except (TypeError, ValueError, OverflowError):
        raise UsageError(f"{where}: {name} must be {kind}, got {value!r}") from None
    if name == "retries" and not 0 <= number <= MAX_RETRIES:
        raise UsageError(f"{where}: retries must be 0..{MAX_RETRIES}, got {value!r}")
    return number


MAX_RETRIES = 20
REAL_TIMEOUT, REAL_RETRIES = 1.0, 2  # a real port's defaults: s to wait for an answer, tries after a timeout


def _number(value: Any, *, whole: bool) -> int | float:
    """A finite number from a file or the environment: ASCII digits only ('٣' and '５' are not 3 and 5), no
    YAML true/false, and a whole number exactly (3.7 retries is an error, not 3)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise TypeError
    if isinstance(value, str):
        text = value.strip()
        if not text.isascii() or (whole and not re.fullmatch(r"[+-]?[0-9]+", text)):
            raise ValueError
        value = float(text) if not whole else int(text)
    number = float(value)
    if not math.isfinite(number) or (whole and not number.is_integer()):
        raise ValueError
    return int(number) if whole else number


def _flag(value: Any, where: str) -> bool:
    """A yes/no option from the environment or a file."""
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("1", "true", "yes", "on"):
        return True
    if text in ("0", "false", "no", "off"):
        return False
    raise UsageError(f"{where}: expected true or false, got {value!r}")


def _from_env() -> ConnectOptions:
    values = {name: _convert(name, os.environ.get(var), var) for name, var in ENV.items()}
    return ConnectOptions(**values)


def _from_config() -> ConnectOptions:
    path = config_file()
    if not path.exists():
        return ConnectOptions()
    data = load_yaml(path) or {}
    if not isinstance(data, dict):
        raise UsageError(f"config file {path}: expected a mapping of option: value")
    unknown = set(data) - set(ENV)
    if unknown:
        raise UsageError(f"config file {path}: unknown option(s) {', '.join(sorted(unknown))}")
    return options_from(data, str(path))


def options_from(data: dict[str, Any], where: str) -> ConnectOptions:
    """ConnectOptions from a mapping read from a file (config, plan); wrong types are a UsageError naming where."""
    return ConnectOptions(**{k: _convert(k, v, where) for k, v in data.items() if k in ENV})


def merge(*layers: ConnectOptions) -> ConnectOptions:
    """First non-None value of each option, layers in priority order."""
    out: dict[str, Any] = {}
    for f in fields(ConnectOptions):
        out[f.name] = next((getattr(layer, f.name) for layer in layers if getattr(layer, f.name) is not None), None)
    return ConnectOptions(**out)


@dataclass(frozen=True)
class Resolved:
    """Everything needed to open a link to one drive."""

    profile: Profile
    settings: LinkSettings
    unit: int
    travel: float | None = None  # soft travel limit (rev) from the environment or config file
    identity_check: bool = True  # check the drive answering against the profile before any write
    confirmed: frozenset[int] = frozenset()  # units whose identity checks were read when the profile was found
    heartbeat_timeout_s: float | None = None  # the watchdog relay's time, where settings.heartbeat names a line
    boost: bool | None = None  # a faster line for long exchanges: True even beside other devices, False never

    @property
    def simulated(self) -> bool:
        return self.settings.port == SIM_PORT


def effective(cli: ConnectOptions) -> ConnectOptions:
    """The options in force: CLI > environment > config file (no profile defaults; nothing checked)."""
    return merge(cli, _from_env(), _from_config())


def resolve(cli: ConnectOptions, *, need_port: bool = True) -> Resolved:
    """Apply CLI > environment > config file > profile defaults, and check every value."""
    opts = effective(cli)
    port = opts.port
    if port is None:
        if need_port:
            raise UsageError("no port given: use --port /dev/ttyUSB0|COM3|tcp://HOST:PORT|sim, or set SERVOTOOL_PORT")
        port = SIM_PORT
    if port != SIM_PORT:
        parse_tcp(port)
    name = opts.profile or (SIM_DEFAULT_PROFILE if port == SIM_PORT else None)
    if name is None:
        raise UsageError("no drive profile given: use --profile (see 'servotool profiles list') or SERVOTOOL_PROFILE")
    profile = load_profile(name)
    settings = LinkSettings(
        port=port,
        line=line_format(opts, profile),
        # the embedded simulator's only delay is this host's own CPU, which a loaded machine can hold up for
        # longer than a real drive ever takes to answer
        timeout=opts.timeout if opts.timeout is not None else (2.0 if port == SIM_PORT else REAL_TIMEOUT),
        retries=opts.retries if opts.retries is not None else (0 if port == SIM_PORT else REAL_RETRIES),
        heartbeat=heartbeat_line(opts, port),
        **rs485(opts),
    )
    if not (math.isfinite(settings.timeout) and 0 < settings.timeout <= 3600):
        raise UsageError(f"bad timeout {settings.timeout:g}: must be > 0 and at most 3600 s")
    if not 0 <= settings.retries <= MAX_RETRIES:
        raise UsageError(f"bad retries {settings.retries}: must be 0..{MAX_RETRIES}")
    if opts.travel is not None and not (math.isfinite(opts.travel) and opts.travel > 0):
        raise UsageError(f"bad travel {opts.travel:g}: must be a number of revolutions > 0")
    return Resolved(
        profile,
        settings,
        check_unit(opts.unit if opts.unit is not None else profile.default_unit),
        identity_check=not opts.no_identity_check,
        travel=opts.travel,
        heartbeat_timeout_s=heartbeat_timeout_s(opts) if settings.heartbeat else None,
        boost=opts.boost,
    )


def heartbeat_line(opts: ConnectOptions, port: str) -> str | None:
    """The control line the heartbeat toggles (dtr, rts), None without one; UsageError for a bad name or a port
    with no control lines (the simulator, RTU over TCP)."""
    if opts.heartbeat is None:
        if opts.heartbeat_timeout_ms is not None:
            raise UsageError("--heartbeat-timeout-ms goes with --heartbeat dtr|rts")
        return None
    line = opts.heartbeat.strip().lower()
    if line not in HEARTBEAT_LINES:
        raise UsageError(f"bad heartbeat '{opts.heartbeat}': use dtr or rts (a control line of the serial adapter)")
    if port == SIM_PORT or port.startswith("tcp://"):
        raise UsageError(
            f"--heartbeat {line} toggles a control line of a USB-RS485 adapter for a watchdog relay: {port} has "
            "none (the simulator and RTU over TCP have no control lines)"
        )
    return line


def heartbeat_timeout_s(opts: ConnectOptions) -> float:
    """The watchdog relay's time in seconds (default HEARTBEAT_TIMEOUT_MS); UsageError outside 200..60000 ms."""
    ms = opts.heartbeat_timeout_ms if opts.heartbeat_timeout_ms is not None else HEARTBEAT_TIMEOUT_MS
    if not (math.isfinite(ms) and 200 <= ms <= 60_000):
        raise UsageError(f"bad heartbeat-timeout-ms {ms:g}: must be 200..60000 ms (the relay's time)")
    return ms / 1000.0


def rs485(opts: ConnectOptions) -> dict[str, Any]:
    """The line habits in LinkSettings' terms: echo (auto: find out), turnaround delay and frame-ending silence."""
    echo = (opts.echo or "auto").lower()
    if echo not in ECHO:
        raise UsageError(f"bad echo '{opts.echo}': use auto, on or off")
    out: dict[str, Any] = {"echo": ECHO[echo]}
    for name, key in (("turnaround_ms", "turnaround"), ("silence_ms", "silence")):
        ms = getattr(opts, name)
        if ms is not None:
            if not (math.isfinite(ms) and 0 <= ms <= 10_000):
                raise UsageError(f"bad {name.replace('_', '-')} {ms:g}: must be 0..10000 ms")
            out[key] = ms / 1000.0
    return out


def check_unit(unit: int) -> int:
    """A Modbus RTU slave address, or UsageError."""
    if not 1 <= unit <= 247:
        raise UsageError(f"bad unit id {unit}: must be 1..247")
    return unit


def line_format(opts: ConnectOptions, profile: Profile) -> LineSettings:
    """The line settings from the options, defaulting to the profile's factory settings; checked."""
    return line_settings(opts, profile.line)


def line_settings(opts: ConnectOptions, defaults: LineSettings) -> LineSettings:
    """The line settings from the options, defaulting to the given ones; checked."""
    baud = opts.baud if opts.baud is not None else defaults.baud
    stopbits = opts.stopbits if opts.stopbits is not None else defaults.stopbits
    parity = PARITIES.get((opts.parity or defaults.parity).upper())
    if parity is None:
        raise UsageError(f"bad parity '{opts.parity}': use N, E or O")
    if not 300 <= baud <= 4_000_000:
        raise UsageError(f"bad baud rate {baud}: must be 300..4000000")
    if stopbits not in (1, 2):
        raise UsageError(f"bad stop bits {stopbits}: must be 1 or 2")
    return LineSettings(baud, parity, stopbits, defaults.bytesize)
