"""Roles by meaning: status bits, the motion route a profile maps, JOG trigger codes."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.errors import MissingRole
from servotool.model.profile import Entry, Profile

# Status-word bit names by meaning: servotool's own names and the vendors' DO-function mnemonics (SD25 SON-O,
# ALM, TGON), so one status role works whatever the drive calls its bits.
STATUS_ALIASES = {
    "servo_on": ("servo_on", "son", "son-o", "run"),
    "fault": ("fault", "alm"),
    "moving": ("moving", "tgon"),
    "jog": ("jog",),
    "identifying": ("identifying",),
}


def status_bit(entry: Entry, meaning: str) -> int | None:
    """The bit of a status entry (format: bits) that carries a meaning (see STATUS_ALIASES), or None."""
    names = STATUS_ALIASES.get(meaning, (meaning,))
    return next((bit for bit, name in sorted(entry.bits.items()) if name.lower() in names), None)


FEATURE = "jog"


DIRECTION_NAMES = {1: "forward", -1: "reverse", 0: "stop"}


def readable_by_role(profile: Profile, roles: tuple[str, ...]) -> list[Entry]:
    """The readable entries the profile maps to these roles, in the roles' order, each once."""
    found: list[Entry] = []
    for role in roles:
        e = profile.role(role)
        if e is not None and e.readable and e not in found:
            found.append(e)
    return found


def is_sim_extension(entry: Entry) -> bool:
    """An entry servotool added for its simulator (source "servotool ..."): not on the real drive."""
    return entry.source.strip().lower().startswith("servotool")


@dataclass(frozen=True)
class SimExtension:
    """Something the simulated drive does that the drive's manual does not document."""

    what: str
    why: str


def sim_extensions(profile: Profile) -> list[SimExtension]:
    """Every simulator extension of a profile: entries and alarms servotool added, and the fake watchdog setting
    where the drive documents no communication timeout."""
    found = [SimExtension(f"entry {e.code} ({e.name})", e.source) for e in profile.entries if is_sim_extension(e)]
    found += [
        SimExtension(f"alarm {a.display} ({a.name})", a.source)
        for a in profile.alarms
        if a.source.strip().lower().startswith("servotool")
    ]
    if profile.role("comm_timeout") is None:
        found.append(
            SimExtension(
                "sim config --fake-watchdog",
                "NOT REAL, off by default: stops host motion after "
                "500 ms of host silence; the real drive documents no communication timeout",
            )
        )
    if profile.dead_man is not None and profile.dead_man.route == "segment":
        found.append(
            SimExtension(
                "sim config --segment-restart",
                "for comparison, off by default: a start edge during a running segment restarts it at once from "
                "where the axis is (the reading before issue 29); the default queues it until the segment has "
                "settled and brakes the segment on a falling edge; the manual documents neither",
            )
        )
    if profile.forced_inputs is not None and profile.forced_inputs.monitor_shows == "forced":
        found.append(
            SimExtension(
                "sim config --di-monitor terminals",
                "NOT IN THE MANUAL, off by default: the input monitor shows the wired terminals while the inputs "
                f"are forced; the manual's words read as the forced levels ({profile.forced_inputs.source})",
            )
        )
    notch = profile.role("notch1_freq")
    if notch is not None:
        width = profile.role("notch1_width")
        depth = profile.role("notch1_depth") or profile.role("notch1_attenuation")
        found.append(
            SimExtension(
                "notch width and depth levels",
                "NOT IN THE MANUAL: it names a frequency, a width level and a depth level per notch "
                f"({notch.code}, {width.code if width else '-'}, {depth.code if depth else '-'}: {notch.source}) but "
                "not the filter they make; the simulator's notch passes depth % at its centre (SD25: cuts depth %, "
                "its sense not stated) over a -3 dB band of width x 10 % of the centre frequency",
            )
        )
    switch = profile.role("gain_switch_mode")
    if switch is not None and profile.role("speed_loop_gain_2") is not None and switch.enum:
        found.append(
            SimExtension(
                f"gain switching ({switch.code})",
                "PARTLY SIMULATED: the simulator runs the conditions 'no switching' (gain 1 or 2) and 'speed' "
                f"(above the switching speed gain 2 at once, below it gain 1 after the delay: {switch.source}); the "
                "others (input, position error, pulse input) act as gain 1 (no GAIN-SEL input or pulse train is "
                "simulated); the switching times (the manual names them, not the transition's shape) are not "
                "modelled: the gains change at once",
            )
        )
    adaptive = profile.role("adaptive_notch")
    if adaptive is not None:
        found.append(
            SimExtension(
                f"adaptive notch ({adaptive.code})",
                "NOT IN THE MANUAL: it names the modes, not how the drive finds a resonance; the simulator's sets "
                "notch 3 at the machine's own resonance (width level 2, depth 0) once the torque command vibrates "
                "(above 20 Hz, 1 % of rated torque RMS) with the servo on",
            )
        )
    if any(profile.role(r) is not None for r in ("friction_comp_fwd", "friction_comp_rev", "torque_offset")):
        found.append(
            SimExtension(
                "friction compensation by direction",
                "NOT IN THE MANUAL: the simulator adds the forward or reverse compensation by the sign of the "
                "speed reference (none within 1 rpm of zero); the manual names the torques, not when they switch",
            )
        )
    if profile.motor is None:
        found.append(
            SimExtension("motor", "no motor data in the profile: the simulator assumes a 400 W, 3000 rpm motor")
        )
    return found


def jog_codes(entry: Entry) -> dict[int, int]:
    """Direction (+1/-1/0) -> raw value of a JOG trigger entry."""
    names = {name.split()[0].lower(): raw for raw, name in entry.enum.items() if name.strip()}
    if all(n in names for n in DIRECTION_NAMES.values()):
        return {d: names[n] for d, n in DIRECTION_NAMES.items()}
    return {1: 1, -1: -1, 0: 0}


def jog_direction(entry: Entry, raw: int) -> int:
    """The direction a raw value written to a JOG trigger entry commands (unknown values stop)."""
    codes = jog_codes(entry)
    if codes == {1: 1, -1: -1, 0: 0}:
        return (raw > 0) - (raw < 0)
    return next((d for d, r in codes.items() if r == raw), 0)


@dataclass(frozen=True)
class MotionRoute:
    """How this profile moves the motor over communication: kind 'trigger' (a JOG trigger), 'segment' (short
    relative position moves, each started by a write) or 'speed' (a speed reference with servo-on), and the entries
    by role."""

    kind: str
    entries: dict[str, Entry]

    @property
    def speed_entry(self) -> Entry:
        return self.entries[{"trigger": "jog_speed", "segment": "segment_speed"}.get(self.kind, "speed_reference")]


ROUTE_ROLES = (
    "jog",
    "jog_speed",
    "speed_reference",
    "servo_on",
    "jog_accel",
    "keepalive",
    "comm_timeout",
    "segment_start",
    "segment_distance",
    "segment_speed",
    "segment_units_per_rev",
)
SEGMENT_ROLES = ("segment_start", "segment_distance", "segment_speed", "servo_on")


def motion_route(profile: Profile, feature: str = FEATURE) -> MotionRoute:
    """The profile's motion route; one clear line when it has none."""
    found = {r: e for r in ROUTE_ROLES if (e := profile.role(r)) is not None}
    if "jog" in found and "jog_speed" in found:
        kind = "trigger"
        found.pop("speed_reference", None)
    elif all(r in found for r in SEGMENT_ROLES):
        kind = "segment"
        found.pop("speed_reference", None)
    elif "speed_reference" in found and "servo_on" in found:
        kind = "speed"
        found.pop("jog", None)
    else:
        raise MissingRole(
            feature,
            "motion_route",
            profile.id,
            f"{feature} needs role 'jog' with 'jog_speed', or 'speed_reference' with 'servo_on', "
            f"which profile {profile.id} does not map",
        )
    return MotionRoute(kind, found)
