"""Checks before identification: alarms, servo state, the axis at rest, and the line's sampling rate."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from servotool.clock import Clock, RealClock
from servotool.drive import Drive
from servotool.errors import UsageError
from servotool.model.codec import raw_to_eng
from servotool.model.profile import Profile
from servotool.model.roles import motion_route, status_bit
from servotool.motion import deadman
from servotool.motion.deadman import DeadManBound
from servotool.motion.jogger import Jogger
from servotool.motion.keepalive import keepalive_interval_s
from servotool.ops import alarms
from servotool.ops.status import servo_is_on

FEATURE = "tune inertia"
# Sampling rate assumed when planning without a measured one (a 38400-baud link).
DEFAULT_SAMPLES_PER_S = 40.0


def check_profile(profile: Profile, method: str, feature: str | None = None) -> None:
    """What the method needs of the profile (roles, motor data), before any I/O; feature names it in messages."""
    p, what = profile, feature or f"{FEATURE} --method {method}"
    # Host identification measures J without the drive's ratio parameter (SDC maps none): it then only reports.
    need = ["speed_feedback", "torque_feedback"]
    need += ["jog_accel"] if method == "host" else ["inertia_ratio", "inertia_id"]
    for role in need:
        p.need_role(role, what)
    if method == "host":
        motion_route(p, what)  # a JOG trigger or speed reference + servo-on
    else:
        status = p.role("servo_status")
        if status is None or status_bit(status, "identifying") is None:
            # Without it the end could only be guessed: a timeout would report failure after a good run.
            raise UsageError(
                f"{FEATURE} --method drive: profile {p.id} maps no status bit that shows the "
                "drive's identification running, so its end cannot be seen over Modbus; use "
                "--method host"
            )
    if p.motor is None:
        raise UsageError(f"{FEATURE} needs the motor data (rated torque, rotor inertia) in profile {p.id}")


def preflight(drive: Drive, method: str) -> None:
    """Profile, link, alarm and servo state, and the dead-man; raises with one clear line."""
    check_profile(drive.profile, method)
    if method == "drive":
        drive_method_dead_man(drive)
    active = active_alarm(drive)
    if active:
        raise UsageError(f"refusing to move: alarm {active} is active (clear it first)")
    if servo_is_on(drive) or (method == "host" and Jogger(drive, feature=FEATURE).servo_already_on()):
        raise UsageError(
            "refusing to move: the servo is on (enabled from elsewhere); switch it off first ('servotool stop')"
        )


def drive_method_dead_man(drive: Drive) -> DeadManBound:
    """The dead-man of the drive's own identification, by the host method's rule (motion/deadman): a drive whose
    route stops nothing moves only with the user's acknowledgement (drive.dead_man_waived), and the link must keep
    the beat. No manual gives the identification's speed: the bound is taken at the motor's rated speed.
    unverified: whether a drive's communication timeout also stops its own identification (no manual says; the
    simulated DSX7E's watchdog does not watch it, its identification ends by itself within Pn515 revolutions)."""
    motor = drive.profile.motor
    speed = motor.rated_speed_rpm if motor is not None else 3000.0
    bound = deadman.bound(drive, speed, min(0.1, keepalive_interval_s(drive)), None, drive.dead_man_waived)
    deadman.check(bound, drive.dead_man_waived)
    return bound


def active_alarm(drive: Drive) -> str | None:
    """'CODE name' of an alarm seen active on two reads in a row (one stray reply is no alarm), else None."""
    state = alarms.confirmed(drive)
    return f"{state.display} {state.name}" if state is not None else None


@dataclass(frozen=True)
class RestCheck:
    """The axis observed with the servo off, before any motion."""

    samples_per_s: float
    speed_noise_rpm: float
    mean_speed_rpm: float
    drift_rev: float | None  # position change over the check (None: no position feedback)
    longest_gap_s: float = 0.0  # the longest time between two samples: how long the host or line may stall
    torque_noise_pct: float = 0.0  # the torque reading's noise at rest (1 sigma, % of rated; 0: it reads steady)


# Readings the rest check takes at least: the speed noise it measures sets the motion's rest band and the excitation
# the line's budget plans for, and its mean says whether the axis moves. From 8 readings (0.3 s at 9600 baud) the
# noise came out anywhere in 0.16-1.1 of the truth, and a still axis with 1 % noise read -13 rpm "moving".
MIN_REST_SAMPLES = 20


def check_at_rest(drive: Drive, timing: Clock | None = None, duration_s: float = 0.3) -> RestCheck:
    """Sample the idle axis: it must stand still (a load torque with no brake drops it as soon as nothing holds it).

    Also measures what the motion plan needs: the link's sampling rate and the speed reading's noise.
    """
    p, timing = drive.profile, timing or RealClock()
    speed_e, torque_e = p.need_role("speed_feedback", FEATURE), p.need_role("torque_feedback", FEATURE)
    pos_e = p.role("position_feedback")
    counts = p.motor.counts_per_rev if p.motor else 1
    pos0 = drive.read_entries([pos_e])[0].raw / counts if pos_e else None
    t0 = timing.now()
    speeds: list[float] = []
    torques: list[float] = []
    gap, last = 0.0, t0
    while timing.now() - t0 < duration_s or len(speeds) < MIN_REST_SAMPLES:
        readings = drive.read_entries([speed_e, torque_e])
        speeds.append(float(raw_to_eng(speed_e, readings[0].raw)))
        torques.append(float(raw_to_eng(torque_e, readings[1].raw)))
        gap, last = max(gap, timing.now() - last), timing.now()
    elapsed = timing.now() - t0
    drift = abs(drive.read_entries([pos_e])[0].raw / counts - pos0) if pos_e and pos0 is not None else None
    mean = sum(speeds) / len(speeds)
    noise = _successive_noise(speeds)
    rest = RestCheck(
        len(speeds) / elapsed if elapsed > 0 else DEFAULT_SAMPLES_PER_S,
        noise,
        mean,
        drift,
        gap,
        _successive_noise(torques),
    )
    moving = (drift is not None and drift > 0.01) or abs(mean) > max(5.0, 4 * noise / math.sqrt(len(speeds)))
    if moving:
        what = f"{drift:.3f} rev in {elapsed:.1f} s" if drift is not None else f"{mean:.0f} rpm"
        raise UsageError(
            f"refusing to move: the axis is moving with the servo off ({what}); a load torque "
            "(gravity?) turns it and no brake holds it: secure the axis first"
        )
    return rest


def _successive_noise(values: list[float]) -> float:
    """A reading's noise (1 sigma) from successive differences: insensitive to a slow drift."""
    diffs = [b - a for a, b in itertools.pairwise(values)]
    return math.sqrt(sum(d * d for d in diffs) / (2 * len(diffs))) if diffs else 0.0
