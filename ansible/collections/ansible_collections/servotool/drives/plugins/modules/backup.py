#!/usr/bin/python
# MIT License (see the servotool repository)
"""servotool.drives.backup: a snapshot of a drive, returned to the control node (plugins/action/backup.py)."""

from __future__ import annotations

DOCUMENTATION = r"""
---
module: backup
short_description: Back up a servo drive's parameters to the control node
description:
  - Reads every parameter of the drive on the managed host and returns a servotool snapshot (deterministic, no time
    stamp inside, so fit for version control, and usable as a golden file and by C(servotool param restore)).
  - The action plugin of the same name writes it on the control node, under I(dest)/MACHINE/ as
    C(PROFILE-unitN-IDENTITY-TIME.yaml) (machine, drive identity and the time it was read, UTC); a snapshot equal
    to the drive's latest one there is not written again and the task reports C(changed=false).
  - The module runs on the managed host and returns the file's text; the control node writes it, as C(fetch)
    brings a file back, without a file on the managed host in between.
version_added: "0.1.0"
extends_documentation_fragment:
  - servotool.drives.connection
options:
  dest:
    description: Folder on the control node for the backups (handled by the action plugin).
    type: path
    required: true
  return_content:
    description: Also return the snapshot's text in the result.
    type: bool
    default: false
  machine:
    description: The machine's name in the file's folder and header (default the inventory host name).
    type: str
  changed_by:
    description: Accepted for module_defaults; a backup changes nothing on the drive.
    type: str
notes:
  - Supports check mode (the drive is read, nothing is written on the control node).
author: servotool
"""

EXAMPLES = r"""
- name: Back up every drive to the control node before changing anything
  servotool.drives.backup:
    port: /dev/ttyUSB0
    profile: sd25
    unit: 1
    dest: "{{ playbook_dir }}/backups"
"""

RETURN = r"""
dest:
  description: The file on the control node (the existing one when the drive had not changed).
  returned: success
  type: str
  sample: backups/press-07/sd25-unit1-So-00_100-20260528T081500Z.yaml
name:
  description: The file's name as the module proposes it (machine folder, profile, unit, identity, time).
  returned: success
  type: str
identity:
  description: The drive's identity entries (code to value as shown), the firmware among them.
  returned: success
  type: dict
entries:
  description: How many parameters the snapshot holds.
  returned: success
  type: int
checksum:
  description: SHA-256 of the values (equal checksums, equal settings).
  returned: success
  type: str
taken:
  description: When the drive was read (UTC).
  returned: success
  type: str
content:
  description: The snapshot's text (from the module; removed by the action plugin unless return_content).
  returned: when return_content
  type: str
"""

import re  # noqa: E402

from ansible.module_utils.basic import AnsibleModule  # noqa: E402
from ansible_collections.servotool.drives.plugins.module_utils.drive import (  # noqa: E402
    CONNECTION_ARGS,
    fail,
    need_servotool,
    open_drive,
)


def slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9.-]+", "_", text).strip("_") or "x"


def main() -> None:
    spec = {**CONNECTION_ARGS, "dest": dict(type="path"), "return_content": dict(type="bool", default=False)}
    module = AnsibleModule(argument_spec=spec, supports_check_mode=True)
    need_servotool(module)
    import socket

    from servotool.clock import utc_now
    from servotool.errors import ServoError
    from servotool.ops import backup

    notices: list[str] = []
    machine = module.params.get("machine") or socket.gethostname()
    try:
        with open_drive(module, notices) as drive:
            taken = backup.take(drive)
            stamp = utc_now().strftime("%Y%m%dT%H%M%SZ")
    except ServoError as exc:
        fail(module, exc, notices=notices)
        return
    taken.machine = machine
    p = drive.profile
    firmware = p.identity.firmware if p.identity else ""
    ident = [firmware] if firmware in taken.identity else sorted(taken.identity)
    key = "-".join(f"{code}_{taken.identity[code]}" for code in ident) or "no-identity"
    name = f"{slug(machine)}/{p.id}-unit{drive.unit}-{slug(key)}-{stamp}.yaml"
    module.exit_json(
        changed=False,
        name=name,
        machine=machine,
        profile=p.id,
        model=p.model,
        unit=drive.unit,
        identity=taken.identity,
        entries=len(taken.values),
        missing=taken.missing,
        checksum=taken.checksum(),
        taken=stamp,
        content=taken.to_snapshot(p),
        notices=notices,
    )


if __name__ == "__main__":
    main()
