"""The simulated drive's monitor registers (Un entries and the status word), refreshed from its plant."""

from __future__ import annotations

from typing import Any

from servotool.model.codec import eng_to_raw
from servotool.model.profile import Entry, Profile
from servotool.model.roles import status_bit
from servotool.sim import terminals
from servotool.sim.alarms import AlarmLog
from servotool.sim.plant import Plant
from servotool.sim.registers import RegisterBank

# Where a profile's status word names no bits (no `bits:` map), the simulator's own layout.
STATUS_BITS = {"servo_on": 0, "fault": 1, "warning": 2, "moving": 3, "jog": 4, "identifying": 5}
BUS_VOLTAGE_V = 311.0  # a 220 V supply, rectified
RATED_CURRENT_A = 2.8  # the current at 100 % torque (a 400 W motor)
SECONDS = {"s": 1.0, "min": 60.0, "h": 3600.0, "ms": 0.001}  # the units a record's time is kept in


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
    _set(profile, bank, "current_rms", abs(p.torque_pct) / 100 * RATED_CURRENT_A)
    _set(profile, bank, "bus_voltage", BUS_VOLTAGE_V)
    # The true speed, not the measured one: a measurement draws from the noise generator, and the outputs (read
    # on every refresh) must not shift the noise a seeded run sees in its readings.
    terminals.refresh_outputs(profile, bank, terminals.DriveState(p.alarm is not None, p.servo_on, p.true_speed_rpm))
    _refresh_alarm_log(profile, bank, alarms, p.alarm)
    _refresh_status_word(profile, bank, p, jogging=jogging, identifying=identifying)


def refresh_inputs(profile: Profile, bank: RegisterBank, monitor: int, encoder: tuple[int, int]) -> None:
    """The input monitor (forced_inputs.monitor) and the absolute encoder's single-turn counts and multi-turn count."""
    if profile.forced_inputs is not None:
        bank.set_live(profile.forced_inputs.monitor_code, monitor)
    for role, value in zip(("encoder_counts", "encoder_turns"), encoder, strict=True):
        entry = profile.role(role)
        if entry is not None:
            bank.set_live(entry.code, value)


def alarm_context(profile: Profile, bank: RegisterBank, p: Plant, run_time_s: float) -> dict[str, float]:
    """What the drive records beside an alarm as it trips (the profile's alarm_log says which it keeps)."""
    current = abs(p.true_torque_pct) / 100 * RATED_CURRENT_A  # true values: no draw from the noise generator
    io = profile.io
    state = terminals.DriveState(True, p.servo_on, p.true_speed_rpm)
    outputs = terminals.output_word(profile, bank, state)
    return {
        "time": run_time_s,
        "speed": p.true_speed_rpm,
        "bus_voltage": BUS_VOLTAGE_V,
        "current": current,
        "current_u": current * 2**0.5,  # a phase's peak, the motor standing at the angle of the U phase's peak
        "current_v": -current * 2**0.5 / 2,
        "inputs": bank.value(io.inputs.monitor) if io is not None and io.inputs is not None else 0,
        "outputs": outputs or 0,
    }


def _refresh_alarm_log(profile: Profile, bank: RegisterBank, alarms: AlarmLog, alarm: str | None) -> None:
    """The current alarm and the past ones, each with what the drive keeps beside it; on a drive that shows one
    record at a time (alarm_log.select), the record its selector names."""
    active = alarm is not None
    records = alarms.records()
    current = records[0] if active and alarms.recorded and records else {"code": alarms.code(alarm)}
    past = alarms.past(active)
    log = profile.alarm_log
    selector = log.select if log is not None else None
    stored, alarms.new_record = alarms.new_record, False
    if selector is not None:
        chosen = int(bank.value(selector.code))
        shown = current if chosen == selector.current else _at(past, chosen - 1)
        _record(profile, bank, profile.role("alarm_code"), shown, stored)
        return
    _record(profile, bank, profile.role("alarm_code"), current, stored)
    n = 1
    while (entry := profile.role(f"alarm_history_{n}")) is not None:
        _record(profile, bank, entry, _at(past, n - 1), stored)
        n += 1


def _at(records: list[dict[str, Any]], index: int) -> dict[str, Any]:
    return records[index] if 0 <= index < len(records) else {"code": 0}


def _record(
    profile: Profile, bank: RegisterBank, code_entry: Entry | None, record: dict[str, Any], stored: bool
) -> None:
    """One alarm record into its code entry and the entries the profile's alarm_log keeps beside it. A record the
    drive keeps in a parameter (SDC's PN58) is written when an alarm enters the log (stored), and is then the
    parameter's value until the next: a host may overwrite it, as it may any parameter."""
    if code_entry is None or (code_entry.cls == "Pn" and not stored):
        return
    _put(bank, code_entry, float(record.get("code", 0)))
    context = profile.alarm_log.context_of(code_entry.code) if profile.alarm_log is not None else {}
    for meaning, code in context.items():
        entry = profile.entry(code)
        value = float(record.get(meaning, 0.0))
        if meaning == "time":
            value /= SECONDS.get(entry.unit, 1.0)
        _put(bank, entry, value)


def _put(bank: RegisterBank, entry: Entry, eng: float) -> None:
    """A value into a monitor, or into a parameter the drive itself keeps (in RAM and EEPROM: a fault log outlives
    a power cycle, and the drive's own log is no host write to count)."""
    raw = eng_to_raw(entry, eng, clamp=True)
    if entry.cls == "Pn":
        for layer in (bank.eeprom, bank.ram, bank.effective):
            layer[entry.code] = raw
        bank.save()
    elif entry.cls != "Fn":
        bank.set_live(entry.code, raw)


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
