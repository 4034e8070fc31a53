#!/usr/bin/python
# MIT License (see the servotool repository)
"""servotool.drives.settings: a drive brought to a desired set of parameters (servotool.ops.apply)."""

from __future__ import annotations

DOCUMENTATION = r"""
---
module: settings
short_description: Bring a servo drive to a desired set of parameters, idempotently
description:
  - Reads the drive's parameters over Modbus RTU, writes only those that differ from the desired set, reads every
    desired value back, and reports C(changed) only when it wrote something.
  - Runs servotool's own library on the managed host (the machine's PC with the RS485 adapter); servotool must be
    installed for the Python that runs the module (C(ansible_python_interpreter)).
  - A write that fails midway is rolled back, so the drive is left as desired or as it was; the failure says which.
  - Every change goes into the drive's change log (C(servotool log)), with C(changed_by) and the machine's name.
version_added: "0.1.0"
extends_documentation_fragment:
  - servotool.drives.connection
options:
  machine:
    description: The machine's name in the change log (default this host's name).
    type: str
  changed_by:
    description: Who makes the change, for the change log (default the remote user at this host).
    type: str
  parameters:
    description:
      - The desired parameters, C(CODE=VALUE) pairs in engineering units as C(servotool param set) takes
        them (Po101 40.0, Po001 "d 1 21", Po001.Y 1).
    type: dict
  file:
    description: A settings file or a servotool backup/snapshot on the managed host, instead of I(parameters).
    type: path
  content:
    description: The text of a settings file or snapshot (e.g. C(lookup('file', 'golden.yaml')) from the control node).
    type: str
  save:
    description:
      - C(true) stores the written values in EEPROM, C(false) keeps them out of it (where the drive allows), left out
        as the drive is set (a backup's values are stored).
    type: bool
notes:
  - Supports check mode (nothing is written; C(changed) says whether something would be) and diff mode (before and
    after, one line per changing parameter with its code, value and unit).
  - Values are compared with what a read shows, the drive's RAM; where EEPROM cannot be read over Modbus (SD25,
    IS620P) a value RAM holds already is left as it is.
author: servotool
"""

EXAMPLES = r"""
- name: The golden gains of a type X press, stored in EEPROM
  servotool.drives.settings:
    port: /dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A10K1XYZ-if00-port0
    profile: sd25
    unit: 1
    save: true
    parameters:
      Po101: 40.0
      Po102: 25.0
    machine: "{{ inventory_hostname }}"

- name: A whole snapshot from the control node
  servotool.drives.settings:
    port: tcp://10.0.2.15:4001
    content: "{{ lookup('file', 'golden/press-x-axis1.yaml') }}"
"""

RETURN = r"""
status:
  description: changed, unchanged or (check mode) would change.
  returned: success
  type: str
  sample: changed
settings:
  description: Each desired parameter before, desired and after (read back), values with their unit.
  returned: success
  type: list
  elements: dict
  sample: [{"code": "Po101", "changed": true, "before": {"value": 60.0, "unit": "Hz"},
            "desired": {"value": 40.0, "unit": "Hz"}, "after": {"value": 40.0, "unit": "Hz"}}]
persisted:
  description: The values written survive a power cycle (null when nothing was written).
  returned: success
  type: bool
verified:
  description: Every desired value read back as desired.
  returned: success
  type: bool
compared:
  description: The memory the comparison read (RAM, or RAM equal to EEPROM on a drive that stores every write).
  returned: success
  type: str
needs_power_cycle:
  description: Parameters written that take effect only after a power cycle.
  returned: success
  type: list
  elements: str
notices:
  description: What opening the drive had to say (a simulated drive, a drive put right after a killed command).
  returned: always
  type: list
  elements: str
rolled_back:
  description: On a failure midway, the parameters written back to their values before the task.
  returned: failure
  type: list
  elements: str
as_before:
  description: On a failure midway, whether the drive was read back as it was before the task.
  returned: failure
  type: bool
"""

from ansible.module_utils.basic import AnsibleModule  # noqa: E402
from ansible_collections.servotool.drives.plugins.module_utils.drive import (  # noqa: E402
    CONNECTION_ARGS,
    DESIRED_ARGS,
    DESIRED_EXCLUSIVE,
    DESIRED_ONE_OF,
    desired_set,
    fail,
    need_servotool,
    open_drive,
    origin,
)


def main() -> None:
    module = AnsibleModule(
        argument_spec={**CONNECTION_ARGS, **DESIRED_ARGS},
        mutually_exclusive=DESIRED_EXCLUSIVE,
        required_one_of=DESIRED_ONE_OF,
        supports_check_mode=True,
    )
    need_servotool(module)
    from servotool.errors import ServoError
    from servotool.ops.apply import CHANGED, WOULD_CHANGE, apply

    notices: list[str] = []
    try:
        with origin(module, "ansible servotool.drives.settings"), open_drive(module, notices) as drive:
            wanted = desired_set(module, drive.profile)
            result = apply(drive, wanted, check=module.check_mode)
    except ServoError as exc:
        fail(module, exc, notices=notices)
        return
    facts = result.as_json()
    facts.pop("changed")
    out = dict(changed=result.status in (CHANGED, WOULD_CHANGE), notices=notices, unit=drive.unit, **facts)
    out["profile"] = drive.profile.id
    if module._diff:
        before, after = result.diff_text()
        where = f"{drive.profile.model} unit {drive.unit}"
        out["diff"] = dict(
            before=before, after=after, before_header=f"{where} (drive)", after_header=f"{where} (desired)"
        )
    module.exit_json(**out)


if __name__ == "__main__":
    main()
