"""Finding drives on a bus: line settings (each profile's factory settings first) x unit ids, one short probe per
id, and the profile each answering drive matches (ops.identity)."""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, field

from servotool.clock import Clock, RealClock
from servotool.connection import (
    PARITIES,
    REAL_RETRIES,
    REAL_TIMEOUT,
    SIM_PORT,
    ConnectOptions,
    effective,
    line_settings,
)
from servotool.errors import DeviceError, ModbusException, UsageError
from servotool.link.master import RtuMaster
from servotool.link.ports import Link, LinkSettings, Trace, parse_tcp
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings, Profile
from servotool.ops.identity import MATCH, Verdict, identify, shipped_profiles

SCAN_TIMEOUT = 0.1  # s per silent id: a drive answers a 1-register read within ~20 ms at 9600
COMMON_BAUDS = (9600, 19200, 38400, 57600, 115200)
COMMON_FORMATS = ("8N1", "8E1", "8O1", "8N2")
PROBE_ADDRESS = 0  # any answer counts, an exception too: it only has to come from the id
_FORMAT = re.compile(r"^([78])([NEO])([12])$")


@dataclass(frozen=True)
class Found:
    """A unit that answered, and what it was identified as."""

    port: str
    line: LineSettings | None  # None over tcp://, where line settings do not apply
    unit: int
    ranked: tuple[Verdict, ...]  # every candidate profile's verdict, best first

    @property
    def best(self) -> Verdict | None:
        return self.ranked[0] if self.ranked and self.ranked[0].outcome == MATCH else None

    def as_json(self) -> dict[str, object]:
        best = self.best
        return {
            "port": self.port,
            "baud": self.line.baud if self.line else None,
            "format": line_format_text(self.line) if self.line else None,
            "unit": self.unit,
            "profile": best.profile.id if best else None,
            "model": best.profile.model if best else None,
            "drive_model": best.model if best else None,
            "firmware": best.firmware if best else None,
            "candidates": [v.as_json() for v in self.ranked],
        }


@dataclass
class ScanResult:
    port: str
    found: list[Found] = field(default_factory=list)
    tried: list[LineSettings | None] = field(default_factory=list)
    noise: list[tuple[LineSettings | None, int, str]] = field(default_factory=list)  # (line, unit, fault kind)
    unusable: list[tuple[LineSettings, str]] = field(default_factory=list)  # settings the port could not open
    probes: int = 0
    seconds: float = 0.0

    def as_json(self) -> dict[str, object]:
        return {
            "port": self.port,
            "found": [f.as_json() for f in self.found],
            "tried": [line_format_text(s, baud=True) if s else "tcp" for s in self.tried],
            "noise": [
                {"setting": line_format_text(s, baud=True) if s else "tcp", "unit": u, "fault": k}
                for s, u, k in self.noise
            ],
            "unusable": [{"setting": line_format_text(s, baud=True), "error": e} for s, e in self.unusable],
            "probes": self.probes,
            "seconds": round(self.seconds, 3),
        }


def line_format_text(line: LineSettings, *, baud: bool = False) -> str:
    text = f"{line.bytesize}{line.parity}{line.stopbits}"
    return f"{line.baud} {text}" if baud else text


def parse_units(text: str) -> list[int]:
    """'1-10,17' -> ids; UsageError for anything outside 1..247."""
    units: list[int] = []
    for part in text.replace(" ", "").split(","):
        m = re.fullmatch(r"(\d+)(?:-(\d+))?", part)
        if not m:
            raise UsageError(f"bad unit range '{part}': use N, N-M or a comma list such as 1-10,17")
        lo, hi = int(m[1]), int(m[2] or m[1])
        if not 1 <= lo <= hi <= 247:
            raise UsageError(f"bad unit range '{part}': ids are 1..247, low to high")
        units += [u for u in range(lo, hi + 1) if u not in units]
    return units


def parse_format(text: str) -> tuple[int, str, int]:
    """'8N1' -> (8, 'N', 1)."""
    m = _FORMAT.match(text.strip().upper())
    if not m:
        raise UsageError(f"bad format '{text}': use data bits, parity, stop bits such as 8N1, 8E1, 8O1 or 8N2")
    return int(m[1]), m[2], int(m[3])


def settings_to_try(
    profiles: list[Profile], bauds: list[int] | None = None, formats: list[str] | None = None
) -> list[LineSettings]:
    """The profiles' factory settings first, then the common ones; narrowed to the given bauds and formats."""
    shapes = [parse_format(f) for f in formats] if formats else None
    out: list[LineSettings] = []
    candidates = [p.line for p in profiles] + [
        LineSettings(b, f[1], int(f[2]), int(f[0])) for b in COMMON_BAUDS for f in COMMON_FORMATS
    ]
    if bauds:
        candidates += [LineSettings(b, f[1], int(f[2]), int(f[0])) for b in bauds for f in COMMON_FORMATS]
    if shapes:
        candidates += [LineSettings(b, p, s, d) for b in (bauds or COMMON_BAUDS) for d, p, s in shapes]
    for line in candidates:
        if bauds and line.baud not in bauds:
            continue
        if shapes and (line.bytesize, line.parity, line.stopbits) not in shapes:
            continue
        if line not in out:
            out.append(line)
    return out


Progress = Callable[[int, int, str], None]  # (probes done, probes in all, the setting being tried)


def scan(
    port: str,
    units: list[int],
    settings: list[LineSettings],
    profiles: list[Profile],
    *,
    timeout: float = SCAN_TIMEOUT,
    progress: Progress | None = None,
    open_link: Callable[[LinkSettings], Link] | None = None,
    clock: Clock | None = None,
) -> ScanResult:
    """Probe every unit id at every line setting (one setting over tcp://), and identify each unit that answers.

    A unit found at one setting is not probed again at the others (a drive has one setting)."""
    tcp = parse_tcp(port) is not None
    lines: list[LineSettings | None] = [None] if tcp else list(settings)
    result = ScanResult(port, tried=lines)
    clock = clock or RealClock()
    total, done, start = len(lines) * len(units), 0, clock.now()
    seen: set[int] = set()
    for line in lines:
        try:
            link = (open_link or _open)(LinkSettings(port, line or LineSettings(), timeout=timeout, retries=0))
        except DeviceError as exc:  # a setting the port cannot do (parity on a pty): the others may work
            if line is None or len(result.unusable) == len(lines) - 1:
                raise
            result.unusable.append((line, str(exc)))
            done += len(units)
            continue
        try:
            for unit in units:
                if progress:
                    progress(done, total, line_format_text(line, baud=True) if line else "tcp")
                done += 1
                if unit in seen:
                    continue
                answered = _probe(link, unit, result, line)
                if answered:
                    seen.add(unit)
                    result.found.append(Found(port, line, unit, tuple(identify(link, unit, profiles))))
        finally:
            link.close()
    if progress:
        progress(total, total, "")
    result.seconds = clock.now() - start
    return result


def _open(settings: LinkSettings, trace: Trace | None = None) -> Link:
    link = RtuMaster(settings, trace=trace)
    link.hurry()
    return link


def _probe(link: Link, unit: int, result: ScanResult, line: LineSettings | None) -> bool:
    """Whether the unit answers one read (an exception answer counts); garbled or stray frames are noted."""
    result.probes += 1
    try:
        link.read(unit, PROBE_ADDRESS, 1)
    except ModbusException:
        return True
    except DeviceError as exc:
        if not exc.fault:
            raise  # not an answer's fault: the port itself failed
        if exc.fault != "silent":
            result.noise.append((line, unit, exc.fault))
        return False
    return True


@dataclass(frozen=True)
class ScanPlan:
    """What a scan will do, from the options."""

    port: str
    units: list[int]
    settings: list[LineSettings]
    profiles: list[Profile]
    timeout: float


def plan(
    options: ConnectOptions, units: str | None = None, bauds: list[int] | None = None, formats: list[str] | None = None
) -> ScanPlan:
    """The scan the options ask for: the port; ids (all 1..247 by default); line settings narrowed by --baud and
    --format (or the global --baud/--parity/--stopbits); the candidate profiles (a --profile file joins the
    shipped ones and goes first); the global --timeout, else a short one."""
    opts = effective(options)
    if not opts.port or opts.port == SIM_PORT:
        raise UsageError("scan needs a real port: --port /dev/ttyUSB0|COM3|tcp://HOST:PORT")
    profiles = shipped_profiles()
    if opts.profile:
        given = load_profile(opts.profile)
        profiles = [given, *(p for p in profiles if p.id != given.id)]
    if not formats and (opts.parity or opts.stopbits):
        parity = PARITIES.get(opts.parity.upper()) if opts.parity else None
        if opts.parity and parity is None:
            raise UsageError(f"bad parity '{opts.parity}': use N, E or O")
        formats = [
            f"8{p}{s}"
            for p in ([parity] if parity else ["N", "E", "O"])
            for s in ([opts.stopbits] if opts.stopbits else [1, 2])
        ]
    bauds = bauds or ([opts.baud] if opts.baud else None)
    for b in bauds or ():
        if not 300 <= b <= 4_000_000:
            raise UsageError(f"bad baud rate {b}: must be 300..4000000")
    timeout = opts.timeout if opts.timeout is not None else SCAN_TIMEOUT
    if not 0 < timeout <= 60:
        raise UsageError(f"bad timeout {timeout:g}: a scan takes > 0 and at most 60 s per id")
    tcp = parse_tcp(opts.port) is not None  # RTU over TCP: line settings do not apply, one pass
    return ScanPlan(
        opts.port,
        parse_units(units) if units else list(range(1, 248)),
        [] if tcp else settings_to_try(profiles, bauds, formats),
        profiles,
        timeout,
    )


def find(
    options: ConnectOptions,
    unit: int,
    profiles: list[Profile],
    *,
    probe_timeout: float = SCAN_TIMEOUT,
    open_link: Callable[[LinkSettings], Link] | None = None,
    trace: Trace | None = None,
) -> Found:
    """The unit on the options' port, read as a scan reads it, before its profile is known: over tcp:// one probe;
    on a serial port one at each candidate profile's factory line (the options' --baud/--parity/--stopbits
    replacing its parts), up to the first that answers. Then one reading of every candidate's identity checks,
    at the options' timeout and retries (ops.identity.choose picks from `ranked`). DeviceError when the unit
    answers at none."""
    opts = effective(options)
    port = opts.port or ""
    tcp = parse_tcp(port) is not None
    lines: list[LineSettings | None] = [None] if tcp else []
    for p in profiles if not tcp else ():
        if (line := line_settings(opts, p.line)) not in lines:
            lines.append(line)
    result = ScanResult(port)
    for line in lines:
        settings = LinkSettings(port, line or LineSettings(), timeout=probe_timeout, retries=0)
        link = open_link(settings) if open_link else _open(settings, trace)
        try:
            answered = _probe(link, unit, result, line)
        finally:
            link.close()
        if not answered:
            continue
        timeout = opts.timeout if opts.timeout is not None else REAL_TIMEOUT
        retries = opts.retries if opts.retries is not None else REAL_RETRIES
        settings = LinkSettings(port, line or LineSettings(), timeout=timeout, retries=retries)
        link = open_link(settings) if open_link else RtuMaster(settings, trace=trace)
        try:
            return Found(port, line, unit, tuple(identify(link, unit, profiles)))
        finally:
            link.close()
    tried = "" if tcp else " at " + ", ".join(line_format_text(x, baud=True) for x in lines if x)
    raise DeviceError(
        f"no answer from unit {unit} on {port}{tried} (wrong unit id, baud/parity, wiring, or the drive is off); "
        f"without --profile the drive must answer to be identified"
    )
