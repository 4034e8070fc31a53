#!/usr/bin/python
# MIT License (see the servotool repository)
"""servotool.drives.facts: who each drive is, its firmware, its alarm and its key monitors, as Ansible facts."""

from __future__ import annotations

DOCUMENTATION = r"""
---
module: facts
short_description: Identity, firmware, alarm and key monitors of servo drives, as facts
description:
  - Reads, for each unit, the drive's identity entries (firmware and model registers, as its servotool profile
    names them), its current alarm with the manual's name, the servo state and the profile's key monitors (speed,
    torque, ...), and returns them as the fact C(servotool_drives), keyed by unit id.
  - Writes nothing.
version_added: "0.1.0"
extends_documentation_fragment:
  - servotool.drives.connection
options:
  profile:
    description: Drive profile id; found from the first unit's answers when left out.
    type: str
  unit:
    description: One Modbus unit id (default the profile's); see I(units) for several.
    type: int
  units:
    description: Several unit ids on the bus, read in turn.
    type: list
    elements: int
  machine:
    description: The machine's name, returned with the facts (default this host's name).
    type: str
  changed_by:
    description: Accepted for module_defaults; reading changes nothing.
    type: str
notes:
  - Supports check mode (it never writes).
author: servotool
"""

EXAMPLES = r"""
- name: What is on the bus
  servotool.drives.facts:
    port: /dev/ttyUSB0
    profile: sd25
    units: [1, 2]

- name: Refuse to go on with an alarm standing
  ansible.builtin.assert:
    that: not ansible_facts.servotool_drives['1'].alarm.active
"""

RETURN = r"""
ansible_facts:
  description: C(servotool_drives), by unit id (as text).
  returned: success
  type: dict
  contains:
    servotool_drives:
      description: For each unit, profile, model, identity (code to value), firmware, alarm, servo_on, monitors.
      type: dict
      sample: {"1": {"profile": "sd25", "model": "SD25", "identity": {"So-00": {"raw": 100, "text": "V1.00"}},
               "firmware": "So-00 = 100", "alarm": {"code": 0, "display": "-", "name": "no alarm", "active": false},
               "servo_on": false, "monitors": {"Do-00": {"name": "Motor speed", "value": 0, "unit": "rpm"}}}}
"""

from ansible.module_utils.basic import AnsibleModule  # noqa: E402
from ansible_collections.servotool.drives.plugins.module_utils.drive import (  # noqa: E402
    CONNECTION_ARGS,
    fail,
    need_servotool,
)


def read_drive(drive, machine):
    """One drive's facts, each read from it now."""
    from servotool.errors import ServoError
    from servotool.model.identity import identity_entries
    from servotool.ops import alarms, monitor, status

    p = drive.profile
    identity = {
        r.entry.code: {"raw": r.raw, "text": r.text} for r in drive.read_entries(identity_entries(p), partial=True)
    }
    firmware = p.identity.firmware if p.identity else ""
    try:
        alarm = (
            {k: v for k, v in alarms.current(drive).as_json().items() if k != "manual"}
            if p.role("alarm_code")
            else None
        )
    except ServoError as exc:  # a drive showing a past alarm record: said, not guessed
        alarm = {"error": str(exc)}
    monitors = {
        r.entry.code: {"name": r.entry.name, "value": r.eng, "unit": r.entry.unit}
        for r in drive.read_entries(monitor.default_entries(p), partial=True)
    }
    return {
        "machine": machine,
        "profile": p.id,
        "model": p.model,
        "vendor": p.vendor,
        "unit": drive.unit,
        "identity": identity,
        "firmware": f"{firmware} = {identity[firmware]['text']}" if firmware in identity else None,
        "alarm": alarm,
        "servo_on": status.servo_is_on(drive),
        "monitors": monitors,
    }


def main() -> None:
    spec = {**CONNECTION_ARGS, "units": dict(type="list", elements="int")}
    module = AnsibleModule(argument_spec=spec, mutually_exclusive=[["unit", "units"]], supports_check_mode=True)
    need_servotool(module)
    import socket

    from servotool.connection import ConnectOptions
    from servotool.errors import ServoError
    from servotool.session import Bus, resolve_or_find

    p = module.params
    units = p.get("units") or ([p["unit"]] if p.get("unit") else None)
    notices: list[str] = []
    options = ConnectOptions(
        port=p["port"],
        profile=p.get("profile"),
        unit=units[0] if units else None,
        baud=p.get("baud"),
        parity=p.get("parity"),
        stopbits=p.get("stopbits"),
        timeout=p.get("timeout"),
        retries=p.get("retries"),
    )
    machine = p.get("machine") or socket.gethostname()
    try:
        resolved, _found = resolve_or_find(options)
        bus = Bus(resolved, units or [resolved.unit], notice=notices.append)
        try:
            found = {str(d.unit): read_drive(d, machine) for d in bus.drives(units or [resolved.unit])}
        finally:
            bus.close()
    except ServoError as exc:
        fail(module, exc, notices=notices)
        return
    module.exit_json(changed=False, ansible_facts={"servotool_drives": found}, notices=notices)


if __name__ == "__main__":
    main()
