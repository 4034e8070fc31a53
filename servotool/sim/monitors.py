"""The simulated drive's monitor registers (Un entries and the status word), refreshed from its plant."""

from __future__ import annotations

from servotool.model.codec import eng_to_raw
from servotool.model.profile import Profile
from servotool.model.roles import status_bit
from servotool.sim.alarms import AlarmLog
from servotool.sim.plant import Plant
from servotool.sim.registers import RegisterBank

# Where a profile's status word names no bits (no `bits:` map), the simulator's own layout.
STATUS_BITS = {"servo_on": 0, "fault": 1, "warning": 2, "moving": 3, "jog": 4, "identifying": 5}


def _set(profile: Profile, bank: RegisterBank, role: str, eng: float) -> None:
    entry = profile.role(role)
    if entry is None or entry.cls == "Pn" or entry.cls == "Fn":
        return
    bank.set_live(entry.code, eng_to_raw(entry, eng, clamp=False))


def refresh(
    profile: Profile, bank: RegisterBank, p: Plant, alarms: AlarmLog, *, jogging: bool, identifying: bool
) -> None:
    """Write the plant's speeds, torque, position, errors and alarms into the monitor registers."""
    _set(profile, bank, "speed_feedback", p.speed_rpm)
    _set(profile, bank, "speed_command", p.speed_command_rpm)
    _set(profile, bank, "torque_feedback", p.torque_pct)
    entry = profile.role("position_feedback")
    if entry is not None and entry.cls not in ("Pn", "Fn"):
        bank.set_live(entry.code, p.position_counts, wrap=True)  # a multi-turn counter wraps
    _set(profile, bank, "following_error", p.following_error_counts)
    _set(profile, bank, "load_rate", p.load_rate_pct)
    _set(profile, bank, "current_rms", abs(p.torque_pct) / 100 * 2.8)
    _set(profile, bank, "bus_voltage", 311.0)
    _set(profile, bank, "alarm_code", alarms.code(p.alarm))
    for n, code in enumerate(alarms.history[:8], start=1):
        _set(profile, bank, f"alarm_history_{n}", code)
    _refresh_status_word(profile, bank, p, jogging=jogging, identifying=identifying)


def refresh_inputs(profile: Profile, bank: RegisterBank, monitor: int, encoder: tuple[int, int]) -> None:
    """The input monitor (forced_inputs.monitor) and the absolute encoder's single-turn counts and multi-turn count."""
    if profile.forced_inputs is not None:
        bank.set_live(profile.forced_inputs.monitor_code, monitor)
    for role, value in zip(("encoder_counts", "encoder_turns"), encoder, strict=True):
        entry = profile.role(role)
        if entry is not None:
            bank.set_live(entry.code, value)


def _refresh_status_word(profile: Profile, bank: RegisterBank, p: Plant, *, jogging: bool, identifying: bool) -> None:
    status = profile.role("servo_status")
    if status is None:
        return
    bits = {
        "servo_on": p.servo_on,
        "fault": p.alarm is not None,
        "moving": abs(p.true_speed_rpm) > 1,
        "jog": jogging,
        "identifying": identifying,
    }
    where = {k: status_bit(status, k) for k in bits} if status.bits else STATUS_BITS
    word = sum(1 << b for k, on in bits.items() if on and (b := where.get(k)) is not None)
    bank.set_live(status.code, word)
