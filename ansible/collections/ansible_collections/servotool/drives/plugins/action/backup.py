# MIT License (see the servotool repository)
"""The control node's half of servotool.drives.backup: run the module on the managed host (where the drive's bus
is), then write the snapshot it returns under dest/MACHINE/ here, as `fetch` brings a file back; a snapshot equal
to the drive's latest one is not written again (changed=false)."""

from __future__ import annotations

import os
import tempfile

from ansible.plugins.action import ActionBase


class ActionModule(ActionBase):
    TRANSFERS_FILES = False

    def run(self, tmp=None, task_vars=None):
        task_vars = task_vars or {}
        result = super().run(tmp, task_vars)
        args = dict(self._task.args)
        dest = args.get("dest")
        if not dest:
            result.update(failed=True, msg="dest is required: the folder on the control node for the backups")
            return result
        args.pop("dest")
        keep_content = bool(args.pop("return_content", False))
        args.setdefault("machine", task_vars.get("inventory_hostname"))
        found = self._execute_module(
            module_name="servotool.drives.backup", module_args=args, task_vars=task_vars, wrap_async=False
        )
        result.update(found)
        if found.get("failed"):
            return result
        content = found["content"]
        path = os.path.join(os.path.expanduser(str(dest)), found["name"])
        folder = os.path.dirname(path)
        prefix = os.path.basename(path).rsplit("-", 1)[0] + "-"  # PROFILE-unitN-IDENTITY-: this drive's files
        latest = _latest(folder, prefix)
        if latest is not None and _read(latest) == content:
            result.update(changed=False, dest=latest, msg="unchanged since the drive's last backup")
        elif self._task.check_mode:
            result.update(changed=True, dest=path, msg="would write a new backup (check mode)")
        else:
            _write(path, content)
            result.update(changed=True, dest=path, msg=f"written to {path}")
        if not keep_content:
            result.pop("content", None)
        return result


def _latest(folder, prefix):
    """The drive's newest backup in folder (names end with a sortable UTC time), or None."""
    try:
        names = sorted(n for n in os.listdir(folder) if n.startswith(prefix) and n.endswith(".yaml"))
    except OSError:
        return None
    return os.path.join(folder, names[-1]) if names else None


def _read(path):
    try:
        with open(path, encoding="utf-8") as fh:
            return fh.read()
    except OSError:
        return None


def _write(path, content):
    """Atomically: a reader sees no file or the whole one."""
    folder = os.path.dirname(path)
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".servotool-backup-", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(content)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
