#!/usr/bin/python
# MIT License (see the servotool repository)
"""servotool.drives.drift: a drive compared with a golden file; changed when they differ."""

from __future__ import annotations

DOCUMENTATION = r"""
---
module: drift
short_description: Compare a servo drive with a golden set of parameters; changed when they differ
description:
  - Reads the parameters a golden file (a settings file or a servotool snapshot) names and compares them with the
    drive; writes nothing. C(changed) is true when the drive differs, so a play can fail or notify on drift.
  - The comparison is the check mode of the settings module (servotool.ops.apply), so C(drift) reports exactly what
    C(settings) would change.
version_added: "0.1.0"
extends_documentation_fragment:
  - servotool.drives.connection
options:
  machine:
    description: The machine's name (unused by a comparison; accepted so module_defaults can give it to every module).
    type: str
  changed_by:
    description: Accepted for module_defaults; a comparison changes nothing.
    type: str
  parameters:
    description: The golden parameters, C(CODE=VALUE) pairs in engineering units.
    type: dict
  file:
    description: A settings file or snapshot on the managed host.
    type: path
  content:
    description: The text of a settings file or snapshot (C(lookup('file', ...)) on the control node).
    type: str
  save:
    description: Accepted for symmetry with the settings module; a comparison writes nothing.
    type: bool
notes:
  - Supports check mode (it never writes) and diff mode (the drive's values against the golden ones).
author: servotool
"""

EXAMPLES = r"""
- name: Verify the golden gains
  servotool.drives.drift:
    port: /dev/ttyUSB0
    profile: sd25
    content: "{{ lookup('file', 'golden/press-x.yaml') }}"
  register: drift
  failed_when: drift.changed
"""

RETURN = r"""
msg:
  description: What differs, each parameter with the drive's value and the golden one, or that none does.
  returned: success
  type: str
  sample: "differs from the golden set: Po101 60.0 Hz (golden 40.0 Hz)"
differences:
  description: Each parameter that differs, the drive's value and the golden one, with their unit.
  returned: success
  type: list
  elements: dict
  sample: [{"code": "Po101", "drive": {"value": 60.0, "unit": "Hz"}, "golden": {"value": 40.0, "unit": "Hz"}}]
compared:
  description: How many parameters were compared.
  returned: success
  type: int
memory:
  description: The memory the comparison read (RAM, or RAM equal to EEPROM).
  returned: success
  type: str
notices:
  description: What opening the drive had to say.
  returned: always
  type: list
  elements: str
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
    from servotool.ops.apply import apply

    notices: list[str] = []
    try:
        with open_drive(module, notices) as drive:
            result = apply(drive, desired_set(module, drive.profile), check=True)
    except ServoError as exc:
        fail(module, exc, notices=notices)
        return
    differences = [
        dict(code=s["code"], name=s["name"], drive=s["before"], golden=s["desired"])
        for s in result.as_json()["settings"]
        if s["changed"]
    ]
    told = [f"{d['code']} {_shown(d['drive'])} (golden {_shown(d['golden'])})" for d in differences]
    out = dict(
        msg=f"differs from the golden set: {', '.join(told)}"
        if told
        else f"as golden ({len(result.settings)} compared)",
        changed=bool(differences),
        differences=differences,
        compared=len(result.settings),
        memory=result.compared,
        missing=result.missing,
        notices=notices,
        unit=drive.unit,
        profile=drive.profile.id,
    )
    if module._diff:
        before, after = result.diff_text()
        where = f"{drive.profile.model} unit {drive.unit}"
        out["diff"] = dict(before=before, after=after, before_header=f"{where} (drive)", after_header="golden")
    module.exit_json(**out)


def _shown(quantity: dict) -> str:
    return f"{quantity['value']} {quantity.get('unit') or ''}".strip()


if __name__ == "__main__":
    main()
