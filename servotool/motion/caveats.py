"""What is not known to work on a real drive before host motion: unverified entries, a missing watchdog."""

from __future__ import annotations

from dataclasses import dataclass

from servotool.model.profile import DeadManRoute, Entry, Profile
from servotool.model.roles import FEATURE, is_sim_extension, motion_route
from servotool.model.setup import requirements


@dataclass(frozen=True)
class MotionCaveats:
    """What is not known to work on a real drive: unverified route entries, and a missing drive-side watchdog."""

    unverified: tuple[tuple[str, Entry, str], ...]  # (role, entry, reason); role "setup" for motion_setup items
    drive_timeout: Entry | None  # None: nothing on the drive stops the motor if the host dies
    power_cycle: tuple[Entry, ...] = ()  # motion_setup entries that take effect after a power cycle
    dead_man: DeadManRoute | None = None  # the profile's dead-man route

    def lines(self) -> list[str]:
        out = [f"{e.code} ({role}): {reason}" for role, e, reason in self.unverified]
        if self.power_cycle:
            codes = ", ".join(e.code for e in self.power_cycle)
            out.append(
                f"{codes} take effect only after a power cycle: if they were changed since the drive was "
                "switched on, it will not move"
            )
        dm = self.dead_man
        if dm is not None and dm.route != "none":
            out.append(
                f"the dead-man ({dm.route}) relies on {dm.source}"
                + (f"; unverified: {dm.unverified}" if dm.unverified else "")
            )
        elif self.drive_timeout is None:
            out.append(
                "this drive has no communication timeout: if this program dies (kill, crash, cable), the "
                "motor keeps running until stopped at the drive; Ctrl-C still stops it"
                + (f" ({dm.source})" if dm is not None else "")
            )
        return out


def motion_caveats(profile: Profile, feature: str = FEATURE) -> MotionCaveats:
    """Unverified entries of the motion route (with their reasons) and the drive-side watchdog, if real."""
    route = motion_route(profile, feature)
    unverified = []
    for role, e in route.entries.items():
        reason = e.unverified or ("a servotool simulator extension, not in the manual" if is_sim_extension(e) else "")
        if reason:
            unverified.append((role, e, reason))
    setup = requirements(profile)
    unverified += [("setup", r.entry, r.item.unverified) for r in setup if r.item.unverified]
    forced = profile.forced_inputs
    if forced is not None and forced.unverified:
        unverified.append(("forced inputs", profile.entry(forced.switch_code), forced.unverified))
    timeout = route.entries.get("comm_timeout")
    return MotionCaveats(
        tuple(unverified),
        timeout if timeout is not None and not is_sim_extension(timeout) else None,
        tuple(r.entry for r in setup if r.entry.effect == "power_cycle"),
        profile.dead_man,
    )
