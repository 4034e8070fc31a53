# MIT License (see the servotool repository)
"""What the servotool.drives modules share: the connection options, opening one drive through servotool's library
(import servotool: the modules run servotool's own functions on the managed host, never parse its CLI output), a
desired set from a task's arguments, and every servotool error as one failure message with its exit status."""

from __future__ import annotations

import os
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

# The options of every module that talks to a drive (module_defaults may give them once for a play: the group
# servotool.drives.drives, meta/runtime.yml).
CONNECTION_ARGS = dict(
    port=dict(type="str", required=True),
    profile=dict(type="str"),
    unit=dict(type="int"),
    baud=dict(type="int"),
    parity=dict(type="str", choices=["N", "E", "O"]),
    stopbits=dict(type="int", choices=[1, 2]),
    timeout=dict(type="float"),
    retries=dict(type="int"),
    machine=dict(type="str"),
    changed_by=dict(type="str"),
)

# The desired set of settings and drift: inline parameters, a file on the managed host, or a file's text (from
# lookup('file', ...) on the control node).
DESIRED_ARGS = dict(
    parameters=dict(type="dict"),
    file=dict(type="path"),
    content=dict(type="str"),
    save=dict(type="bool"),
)
DESIRED_EXCLUSIVE = [["parameters", "file", "content"]]
DESIRED_ONE_OF = [["parameters", "file", "content"]]


def need_servotool(module):
    """servotool importable by the managed host's Python, else a failure that says how to get it there."""
    try:
        import servotool  # noqa: F401
    except ImportError:
        module.fail_json(
            msg=f"servotool is not installed for {sys.executable}: install it there (pip install servotool, or "
            "pip install -e CHECKOUT), or point ansible_python_interpreter at a Python that has it"
        )


@contextmanager
def origin(module, source):
    """Who, from where and on which machine, for the drive's change log (servotool.ops.changelog)."""
    from servotool.ops.changelog import origin as named

    params = module.params
    with named(who=params.get("changed_by"), source=source, machine=params.get("machine")):
        yield


@contextmanager
def open_drive(module, notices):
    """The drive the task names, opened through servotool's session: the profile found from the drive when none
    is given, its identity checked before anything is written; what opening it had to say goes to notices."""
    from servotool.connection import ConnectOptions
    from servotool.session import open_drives, resolve_or_find

    p = module.params
    options = ConnectOptions(
        port=p["port"],
        profile=p.get("profile"),
        unit=p.get("unit"),
        baud=p.get("baud"),
        parity=p.get("parity"),
        stopbits=p.get("stopbits"),
        timeout=p.get("timeout"),
        retries=p.get("retries"),
    )
    resolved, _found = resolve_or_find(options)
    with open_drives(resolved, [resolved.unit], notice=notices.append) as (drive,):
        yield drive


def desired_set(module, profile):
    """The task's desired set (servotool.ops.desired): parameters, a settings file or backup on the managed host,
    or a file's text."""
    from servotool.ops import desired

    p = module.params
    if p.get("parameters") is not None:
        data = {"parameters": p["parameters"]}
        if p.get("save") is not None:
            data["save"] = p["save"]
        return desired.from_mapping(data, "the task's parameters")
    if p.get("file"):
        found = desired.load(Path(p["file"]), profile)
    else:
        fd, name = tempfile.mkstemp(suffix=".yaml", prefix="servotool-golden-")
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(p["content"])
            found = replace(desired.load(Path(name), profile), source="the task's content")
        finally:
            os.unlink(name)
    return found if p.get("save") is None else replace(found, save=p["save"])


def fail(module, exc, **facts):
    """A servotool error as the task's failure: its one line, its exit status and what it says of the drive."""
    extra = {}
    if hasattr(exc, "as_before"):  # servotool.ops.apply.ApplyFailed
        extra = dict(rolled_back=list(exc.rolled_back), as_before=bool(exc.as_before), written=list(exc.written))
    module.fail_json(msg=str(exc), exit_status=getattr(exc, "exit_code", 1), **facts, **extra)
