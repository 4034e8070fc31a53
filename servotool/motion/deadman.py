"""What stops the motor if this program stops: the profile's dead-man route and the bound it gives.

The bound is computed before any motion from the route (the profile's `dead_man` section), the speed, the beat
period and the ramp, and is returned as facts; the CLI words them ("if this program stops, the motor stops within
X rev (Y s)"). A route that stops nothing (route none) needs the user's explicit acknowledgement (--no-dead-man).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.profile import DeadManRoute, Profile
from servotool.model.quantity import quantity

# Exchanges one beat cycle of host motion makes (the beat, at most two writes re-arming a segment, the alarm check and
# the speed read).
EXCHANGES_PER_BEAT = 4
# Bytes on the wire of one exchange (request + reply of a short read or write) and the turnaround allowance.
EXCHANGE_BYTES = 17
TURNAROUND_S = 0.005
NO_ROUTE = DeadManRoute(route="none", reason="the profile describes no dead-man route", source="")


@dataclass(frozen=True)
class DeadManBound:
    """The dead-man facts of one motion: the route, and how far/long the motor runs on if the host dies now."""

    route: str  # drive_timeout | segment | heartbeat | none
    speed_rpm: float
    beat_s: float
    link_cycle_s: float  # the host's estimated time for one beat cycle on this link
    stop_rev: float | None  # None: nothing on the drive stops the motor
    stop_s: float | None
    reason: str
    source: str
    unverified: str
    if_host_dies: str
    waived: bool = False  # route none, acknowledged with --no-dead-man
    # What else bounds the motion (motion/protect, motion/forced_inputs): the drive's overtravel fence either way
    # of the start and its speed limit, set for the motion's duration, and those facts and warnings in words.
    fence_rev: float | None = None
    speed_limit_rpm: float | None = None
    limits: tuple[str, ...] = ()
    relay_s: float | None = None  # route heartbeat: the watchdog relay's time

    @property
    def bounded(self) -> bool:
        return self.stop_rev is not None

    def as_json(self) -> dict[str, object]:
        return {
            "route": self.route,
            "bounded": self.bounded,
            "stop_within": quantity(None if self.stop_rev is None else round(self.stop_rev, 3), "rev"),
            "stop_within_time": quantity(None if self.stop_s is None else round(self.stop_s, 3), "s"),
            "speed": quantity(round(self.speed_rpm, 1), "rpm"),
            "beat": quantity(round(self.beat_s, 4), "s"),
            "link_cycle": quantity(round(self.link_cycle_s, 4), "s"),
            "waived": self.waived,
            "reason": self.reason,
            "source": self.source,
            "unverified": self.unverified,
            "fence_rev": None if self.fence_rev is None else round(self.fence_rev, 3),
            "speed_limit_rpm": self.speed_limit_rpm,
            "limits": list(self.limits),
        }


def route_of(profile: Profile) -> DeadManRoute:
    """The profile's dead-man route; a profile that describes none has none."""
    return profile.dead_man or NO_ROUTE


def link_cycle_s(drive: Drive) -> float:
    """How long one beat cycle takes on this link: its exchanges at the line's baud rate, with turnarounds."""
    settings = getattr(drive.link, "settings", None)
    baud = settings.line.baud if settings is not None else drive.profile.line.baud
    return EXCHANGES_PER_BEAT * (EXCHANGE_BYTES * 11.0 / baud + TURNAROUND_S)


def stop_time_s(speed_rpm: float, ramp_ms: float | None, reference_rpm: float) -> float:
    """Time to ramp down from speed_rpm with a ramp time ramp_ms per reference_rpm (Profile.ramp_rpm); without a
    known ramp, one second per 1000 rpm."""
    if ramp_ms is None:
        return abs(speed_rpm) / 1000.0
    return ramp_ms / 1000.0 * abs(speed_rpm) / reference_rpm


SEGMENT_BRAKE_LAG_S = 0.02  # a braked segment stops this much later than its ramp alone (the speed loop's lag)
SEGMENT_SETTLE_S = 0.2  # a queued segment starts once the braked one has settled: within this (time bound only)
SEGMENT_BEATS = 3.0  # a segment covers this many beat periods at speed, so a late beat never stutters the motion


def braking_rev(speed_rpm: float, ramp_ms: float | None, reference_rpm: float) -> float:
    """Distance to ramp down from speed_rpm (see stop_time_s; reference_rpm: the speed the ramp time is for)."""
    return abs(speed_rpm) / 60.0 * stop_time_s(speed_rpm, ramp_ms, reference_rpm) / 2.0


def segment_rev(speed_rpm: float, beat_s: float, ramp_ms: float | None, reference_rpm: float) -> float:
    """The length of each re-armed segment: SEGMENT_BEATS beats at speed, then room to stop."""
    return abs(speed_rpm) / 60.0 * SEGMENT_BEATS * beat_s + braking_rev(speed_rpm, ramp_ms, reference_rpm)


def drive_timeout_s(drive: Drive) -> float | None:
    """The drive's communication timeout in seconds (role comm_timeout), None when absent or disabled."""
    entry = drive.profile.role("comm_timeout")
    if entry is None:
        return None
    value = float(raw_to_eng(entry, drive.read_entries([entry])[0].raw)) / 1000.0
    return value if value > 0 else None


UNREAD = -1.0  # timeout_s not given: read it from the drive


def bound(
    drive: Drive,
    speed_rpm: float,
    beat_s: float,
    ramp_ms: float | None,
    waived: bool = False,
    timeout_s: float | None = UNREAD,
) -> DeadManBound:
    """The dead-man bound of a motion at speed_rpm on this drive (timeout_s: the drive's communication timeout when
    already read); see check() for when it cannot be kept."""
    route = route_of(drive.profile)
    cycle = link_cycle_s(drive)
    reference = drive.profile.ramp_rpm()
    stop_s = stop_time_s(speed_rpm, ramp_ms, reference)
    rev = s = None
    kind = route.route
    if kind == "drive_timeout":
        timeout = drive_timeout_s(drive) if timeout_s == UNREAD else timeout_s
        if timeout is None:
            kind = "none"  # the watchdog is switched off on this drive: nothing stops the motor
        else:
            s = timeout + stop_s
            rev = abs(speed_rpm) / 60.0 * (timeout + stop_s / 2.0)
    elif kind == "segment":
        # The running segment, re-armed just before the host died: restarted from where the axis was, or (the
        # stricter reading of the firmware) braked and followed by the queued one once settled.
        braked = braking_rev(speed_rpm, ramp_ms, reference) + abs(speed_rpm) / 60.0 * SEGMENT_BRAKE_LAG_S
        rev = segment_rev(speed_rpm, beat_s, ramp_ms, reference) + braked
        s = SEGMENT_BEATS * beat_s + 2.0 * stop_s + SEGMENT_SETTLE_S
    if kind == "none" and drive.heartbeat_timeout_s is not None and drive.heartbeat_line is not None:
        return heartbeat_bound(drive, speed_rpm, beat_s, stop_s, cycle)
    return DeadManBound(
        kind,
        abs(speed_rpm),
        beat_s,
        cycle,
        rev,
        s,
        route.reason,
        route.source,
        route.unverified,
        route.if_host_dies,
        waived and kind == "none",
    )


def heartbeat_bound(drive: Drive, speed_rpm: float, beat_s: float, stop_s: float, cycle: float) -> DeadManBound:
    """A drive without a dead-man of its own, with a watchdog relay on the adapter's control line (--heartbeat):
    the relay drops the drive's enable (or main contactor) its time after the toggles stop."""
    relay_s = drive.heartbeat_timeout_s or 0.0
    line = drive.heartbeat_line.name if drive.heartbeat_line is not None else "?"
    return DeadManBound(
        "heartbeat",
        abs(speed_rpm),
        beat_s,
        cycle,
        abs(speed_rpm) / 60.0 * (relay_s + stop_s / 2.0),
        relay_s + stop_s,
        f"--heartbeat {line}: a watchdog relay drops the drive's enable input or main contactor "
        f"{relay_s * 1000:g} ms after the adapter's {line.upper()} line stops toggling",
        "servotool --heartbeat (README: the hardware dead-man)",
        "the relay's wiring and time are the user's (--heartbeat-timeout-ms); how the drive stops when its enable or "
        "main power is cut (coast, dynamic brake, ramp) is its own setting, taken as its ramp here; a host that hangs "
        "with the line high holds a relay that times from the line's fall",
        "the relay drops the drive's enable within the printed time",
        relay_s=relay_s,
    )


def motion_bound(drive: Drive, speed_rpm: float, ramp_s: float) -> DeadManBound:
    """The checked bound of a planned motion (identification, step check: ramp_s to reach speed_rpm) at the
    drive's beat rate, as its Jogger arms it."""
    from servotool.motion.keepalive import keepalive_interval_s

    ramp_ms = ramp_s * 1000.0 * drive.profile.ramp_rpm() / abs(speed_rpm)  # the parameter's reading
    b = bound(drive, speed_rpm, min(0.1, keepalive_interval_s(drive)), ramp_ms, drive.dead_man_waived)
    check(b, drive.dead_man_waived)
    return b


def largest_fitting_speed(speed_rpm: float, fits: Callable[[float], bool], floor_rpm: float) -> float | None:
    """The highest speed up to speed_rpm (to 1 %) at which `fits` holds (it holds at lower speeds if at higher);
    None where not even floor_rpm fits."""
    if fits(speed_rpm):
        return speed_rpm
    if floor_rpm >= speed_rpm or not fits(floor_rpm):
        return None
    lo, hi = floor_rpm, speed_rpm
    while hi - lo > 0.01 * hi:
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return max(floor_rpm, float(int(lo)))  # whole rpm, as printed


def timeout_remedy(drive: Drive, b: DeadManBound) -> str:
    """What else shortens a bound than a lower speed, as words after a list of remedies: the drive's own watchdog
    where it is the route ("" elsewhere)."""
    entry = drive.profile.role("comm_timeout")
    if b.route != "drive_timeout" or entry is None:
        return ""
    return f", or a shorter watchdog {entry.code} (param set {entry.code}=...; it stops the motor after that long)"


def check(b: DeadManBound, waived: bool) -> None:
    """Refuse a motion whose dead-man cannot be kept: no route and no acknowledgement, or a link too slow for the
    beat the bound needs (with the alternatives)."""
    if b.route == "none":
        if not waived:
            what = b.if_host_dies or "the motor keeps running until stopped at the drive"
            raise UsageError(
                f"no dead-man on this drive ({b.reason}): if this program dies (kill, crash, cable), "
                f"{what}. Pass --no-dead-man to move anyway, with an E-stop at hand"
            )
        return
    if b.relay_s is not None:  # a toggle needs no exchange: the loop's exchanges must fit well inside the relay's time
        if b.link_cycle_s * 4 > b.relay_s:
            raise UsageError(
                f"this link cannot keep the heartbeat: one beat cycle takes about {b.link_cycle_s * 1000:.0f} ms, "
                f"the watchdog relay's {b.relay_s * 1000:g} ms needs a toggle every {b.relay_s * 250:.0f} ms; use a "
                "faster baud rate or a longer --heartbeat-timeout-ms"
            )
        return
    if b.link_cycle_s * 2 > b.beat_s:
        raise UsageError(
            f"this link cannot keep the dead-man beat: one beat cycle takes about "
            f"{b.link_cycle_s * 1000:.0f} ms, the bound needs a beat every {b.beat_s * 1000:.0f} ms; "
            "use a faster baud rate, a longer drive timeout or a longer segment, or a slower speed"
        )


def with_limits(
    b: DeadManBound, fence_rev: float | None, speed_limit_rpm: float | None, limits: tuple[str, ...]
) -> DeadManBound:
    """The bound with what else bounds the motion (see DeadManBound.fence_rev)."""
    return replace(b, fence_rev=fence_rev, speed_limit_rpm=speed_limit_rpm, limits=limits)


def sentence(b: DeadManBound) -> str:
    """The bound in words, as printed before moving."""
    fence = f" until the drive's overtravel fence at ±{b.fence_rev:.2f} rev stops it" if b.fence_rev else ""
    if b.stop_rev is None:
        return (
            "NO DEAD-MAN (--no-dead-man): if this program stops, the motor keeps running at "
            f"{b.speed_rpm:.0f} rpm " + (fence[1:] if fence else "until stopped at the drive")
        )
    text = f"if this program stops, the motor stops within {b.stop_rev:.2f} rev ({b.stop_s:.2f} s)"
    return text + (f"; at worst it runs at ≤ {b.speed_rpm:g} rpm{fence}" if fence else "")


def lines(b: DeadManBound) -> list[str]:
    """The bound and what else bounds the motion, one line each, as printed before moving."""
    return [sentence(b), *(f"  {line}" for line in b.limits)]
