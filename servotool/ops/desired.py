"""A desired set of drive settings: the parameters a drive should hold, in engineering units, and whether to store
them in EEPROM; read from a settings file, a backup or snapshot, or given as a mapping (an Ansible task's).

A settings file:

    servotool_settings: 1
    profile: sd25          # optional: the drive's profile must be this one
    unit: 1                # optional: the unit it is for (a fleet inventory or the command line names it too)
    save: true             # true: store in EEPROM, false: keep out of it, absent: as the drive is set
    parameters:
      Po101: 40.0          # engineering units, as `param set` takes them ("40 Hz", "d 1 21", Po001.Y: 1)

A backup or snapshot is a desired set too: its raw values, stored in EEPROM (it holds what the drive keeps), without
the EEPROM switch (which redirects every write) and axis-specific entries (copy: false), as `param restore` does.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from servotool.errors import UsageError
from servotool.files import load_yaml
from servotool.model.codec import split_field
from servotool.model.profile import Profile

FORMAT = 1
KEYS = ("servotool_settings", "profile", "unit", "save", "parameters")


@dataclass(frozen=True)
class DesiredSet:
    """What a drive should hold: CODE=VALUE assignments (engineering units, or raw register values from a backup),
    the EEPROM choice, and the profile and unit it names (None: any)."""

    assignments: tuple[str, ...]
    save: bool | None = None
    raw: bool = False
    profile: str | None = None
    unit: int | None = None
    source: str = "inline"  # the file it came from, for messages
    skipped: tuple[tuple[str, str], ...] = field(default_factory=tuple)  # (code, why) a backup's entries left out
    from_backup: bool = False

    @property
    def codes(self) -> list[str]:
        return [a.partition("=")[0] for a in self.assignments]

    def check_profile(self, profile: Profile) -> None:
        """UsageError when the set names another profile than the drive's."""
        if self.profile is not None and self.profile.lower() != profile.id.lower():
            raise UsageError(f"{self.source}: settings for profile {self.profile}, but the drive's is {profile.id}")


def from_mapping(data: Any, where: str, *, profile: str | None = None) -> DesiredSet:
    """A desired set from a settings file's content (or an Ansible task's arguments); UsageError naming `where`
    for anything wrong, before any drive is touched."""
    if not isinstance(data, dict):
        raise UsageError(f"{where}: expected a mapping with 'parameters', got {type(data).__name__}")
    unknown = sorted(set(map(str, data)) - set(KEYS))
    if unknown:
        raise UsageError(f"{where}: unknown key(s) {', '.join(unknown)} (expected {', '.join(KEYS[1:])})")
    version = data.get("servotool_settings", FORMAT)
    if version != FORMAT:
        raise UsageError(f"{where}: servotool_settings {version!r} is not a format this servotool reads ({FORMAT})")
    params = data.get("parameters")
    if not isinstance(params, dict) or not params:
        raise UsageError(f"{where}: 'parameters' must map each code to its value (CODE: VALUE), and name one at least")
    save = data.get("save")
    if save is not None and not isinstance(save, bool):
        raise UsageError(f"{where}: save must be true, false or left out, not {save!r}")
    unit = data.get("unit")
    if unit is not None and (isinstance(unit, bool) or not isinstance(unit, int) or not 1 <= unit <= 247):
        raise UsageError(f"{where}: unit must be a Modbus unit id 1..247, not {unit!r}")
    named = data.get("profile", profile)
    if named is not None and not isinstance(named, str):
        raise UsageError(f"{where}: profile must be a profile id, not {named!r}")
    assignments = []
    for code, value in params.items():
        if isinstance(value, bool) or value is None or not isinstance(value, int | float | str):
            raise UsageError(f"{where}: {code}: {value!r} is not a value (a number, or text as the manual writes it)")
        assignments.append(f"{code}={value}")
    return DesiredSet(tuple(assignments), save, False, named, unit, where)


def from_backup(path: Path, profile: Profile) -> DesiredSet:
    """A backup or snapshot as a desired set: its raw values, stored in EEPROM, without the EEPROM switch and the
    axis-specific entries (as `param restore` leaves them)."""
    from servotool.ops.backup import load

    b = load(path, profile)
    assignments, skipped = [], []
    for code, raw in b.values.items():
        e = profile.entry(code)
        if not e.writable:
            continue
        if profile.persistence.is_switch(e.code):
            skipped.append((e.code, "the EEPROM switch: apply sets it for its own writes and leaves it as it was"))
            continue
        if not e.copy:
            skipped.append((e.code, "axis-specific: set it by name in a settings file"))
            continue
        assignments.append(f"{e.code}={raw}")
    return DesiredSet(tuple(assignments), True, True, b.profile, b.unit, str(path), tuple(skipped), True)


def load(path: Path, profile: Profile | None = None) -> DesiredSet:
    """A settings file, or a backup or snapshot (whose profile is then needed to read it); every problem is one
    UsageError naming the file, before any drive is touched."""
    data = load_yaml(path)
    if isinstance(data, dict) and "servotool_backup" in data:
        if profile is None:
            raise UsageError(f"{path}: a backup: its drive's profile is needed to read it")
        return from_backup(path, profile)
    return from_mapping(data, str(path))


def profile_named(path: Path) -> str | None:
    """The profile a settings file or backup names, None when it names none."""
    data = load_yaml(path)
    found = data.get("profile") if isinstance(data, dict) else None
    return found if isinstance(found, str) else None


def check(desired: DesiredSet, profile: Profile) -> None:
    """Every code of the set is a settable parameter of this profile (UsageError otherwise); values are checked
    against the drive's current ones when it is planned (ops.params.prepare_set)."""
    desired.check_profile(profile)
    for code in desired.codes:
        entry, _field = split_field(profile, code)
        if entry.cls != "Pn" or not entry.writable:
            raise UsageError(f"{desired.source}: {entry.code} ({entry.name}) is not a settable parameter")
