"""Link health of one drive: round-trip times, echo, errors and retries over N requests, the request rate reached
against what the line settings allow, and the USB adapter's latency timer (Linux)."""

from __future__ import annotations

import os
import statistics
from collections.abc import Callable
from dataclasses import dataclass, field

from servotool.clock import Clock, RealClock
from servotool.connection import SIM_PORT, ConnectOptions, check_unit, effective, line_settings
from servotool.errors import DeviceError, ModbusException, UsageError
from servotool.link.master import RtuMaster
from servotool.link.ports import SYSFS_USB_SERIAL, LinkSettings, parse_tcp, usb_latency_ms
from servotool.model.identity import read_plan
from servotool.model.loader import load_profile
from servotool.model.profile import LineSettings, Profile
from servotool.model.quantity import quantity
from servotool.ops.scan import PROBE_ADDRESS


@dataclass(frozen=True)
class LatencyTimer:
    """A USB-serial adapter's latency timer (Linux sysfs), in ms."""

    path: str
    ms: int


@dataclass
class Health:
    """What N requests to one unit showed."""

    port: str
    line: LineSettings | None  # None over tcp://
    unit: int
    address: int
    registers: int
    count: int
    rtts: list[float] = field(default_factory=list)  # s, requests that got an answer (an exception too)
    exceptions: int = 0
    failures: int = 0  # requests with no usable answer after the retries
    frames: int = 0  # frames sent in all: tries and confirming reads included
    echo: bool | None = None
    seconds: float = 0.0
    latency: LatencyTimer | None = None

    @property
    def retries(self) -> int:
        return max(0, self.frames - self.count)

    @property
    def achieved_rate(self) -> float:
        return self.count / self.seconds if self.seconds > 0 else 0.0

    @property
    def theoretical_rate(self) -> float | None:
        """Requests/s the line allows for this read: wire time of request and reply plus the RTU silences (the
        drive's own processing comes on top). None over tcp://."""
        if self.line is None:
            return None
        bits = 1 + self.line.bytesize + (self.line.parity != "N") + self.line.stopbits
        gap = 3.5 * bits / self.line.baud if self.line.baud <= 19200 else 0.00175
        return 1.0 / ((8 + 5 + 2 * self.registers) * bits / self.line.baud + 2 * gap)

    def rtt_ms(self) -> dict[str, float] | None:
        if not self.rtts:
            return None
        ms = [t * 1000 for t in self.rtts]
        return {"min": round(min(ms), 3), "median": round(statistics.median(ms), 3), "max": round(max(ms), 3)}

    def as_json(self) -> dict[str, object]:
        theory = self.theoretical_rate
        return {
            "port": self.port,
            "baud": self.line.baud if self.line else None,
            "format": f"{self.line.bytesize}{self.line.parity}{self.line.stopbits}" if self.line else None,
            "unit": self.unit,
            "address": self.address,
            "registers": self.registers,
            "requests": self.count,
            "answered": len(self.rtts),
            "exceptions": self.exceptions,
            "failures": self.failures,
            "error_rate": round(self.failures / self.count, 4),
            "retries": self.retries,
            "retry_rate": round(self.retries / self.count, 4),
            "echo": self.echo,
            "rtt": {**rtt, "unit": "ms"} if (rtt := self.rtt_ms()) is not None else None,
            "achieved_rate": quantity(round(self.achieved_rate, 1), "requests/s"),
            "theoretical_rate": quantity(round(theory, 1) if theory else None, "requests/s"),
            "latency_timer": {"path": self.latency.path, "value": self.latency.ms, "unit": "ms"}
            if self.latency
            else None,
        }


def link_settings(options: ConnectOptions) -> tuple[LinkSettings, int, Profile | None]:
    """Port, line settings (the profile's factory ones when --profile is given, else 9600 8N1), unit."""
    opts = effective(options)
    if not opts.port:
        raise UsageError("doctor needs a port: --port /dev/ttyUSB0|COM3|tcp://HOST:PORT")
    if opts.port == SIM_PORT:
        raise UsageError(
            "doctor checks a line: start 'servotool sim serve --port tcp://127.0.0.1:0' and give its tcp:// port"
        )
    parse_tcp(opts.port)
    profile = load_profile(opts.profile) if opts.profile else None
    line = line_settings(opts, profile.line if profile else LineSettings())
    settings = LinkSettings(
        opts.port,
        line,
        timeout=opts.timeout if opts.timeout is not None else 1.0,
        retries=opts.retries if opts.retries is not None else 2,
        echo=None,
    )
    unit = check_unit(opts.unit if opts.unit is not None else (profile.default_unit if profile else 1))
    return settings, unit, profile


def check(
    settings: LinkSettings,
    unit: int,
    profile: Profile | None,
    count: int,
    progress: Callable[[int], None] | None = None,
    clock: Clock | None = None,
) -> Health:
    """Send `count` reads to the unit and measure. The read is the profile's first identity block (what a drive
    of that family has), else one register at address 0; an exception answer is an answer."""
    if count < 1:
        raise UsageError("--count must be at least 1")
    address, registers = PROBE_ADDRESS, 1
    if profile and profile.identity:
        address, registers, _checks = read_plan(profile.identity.checks, profile.limits.max_read)[0]
    tcp = parse_tcp(settings.port) is not None
    health = Health(
        settings.port,
        None if tcp else settings.line,
        unit,
        address,
        registers,
        count,
        latency=None if tcp else latency_timer(settings.port),
    )
    clock = clock or RealClock()
    link = RtuMaster(settings)
    try:
        start = clock.now()
        for i in range(count):
            t0 = clock.now()
            try:
                link.read(unit, address, registers)
                health.rtts.append(clock.now() - t0)
            except ModbusException:
                health.rtts.append(clock.now() - t0)
                health.exceptions += 1
            except DeviceError as exc:
                if not exc.fault:
                    raise
                health.failures += 1
            if progress:
                progress(i + 1)
        health.seconds = clock.now() - start
        health.frames, health.echo = link.requests, link.echo
    finally:
        link.close()
    return health


def latency_timer(port: str) -> LatencyTimer | None:
    """The USB-serial adapter's latency timer (link.ports.usb_latency_ms), with the file that sets it."""
    ms = usb_latency_ms(port)
    if ms is None:
        return None
    return LatencyTimer(str(SYSFS_USB_SERIAL / os.path.basename(os.path.realpath(port)) / "latency_timer"), ms)
