"""Loading profiles: built-in ids and files, parsed and validated once per process."""

from __future__ import annotations

from pathlib import Path

from servotool.errors import FileProblem, ProfileError
from servotool.files import load_yaml
from servotool.model.profile import Profile
from servotool.model.schema import parse_profile


def builtin_dir() -> Path:
    """Folder of the profiles shipped with the package (or, in a source checkout, the top-level profiles/)."""
    here = Path(__file__).resolve().parent.parent   # the servotool package
    installed = here / "profiles"
    return installed if installed.is_dir() else here.parent / "profiles"


def builtin_ids() -> list[str]:
    return sorted(p.stem for p in builtin_dir().glob("*.yaml"))


def read_profile(path: Path) -> tuple[Profile | None, list[str]]:
    """Parse a profile file; return it (or None) and the list of problems."""
    try:
        data = load_yaml(path)
    except FileProblem as exc:
        return None, [str(exc)]
    profile, problems = parse_profile(data, str(path))
    if profile is not None:
        profile.path = path
        if profile.id != path.stem:
            return None, [f"{path}: id: '{profile.id}' does not match the file name '{path.stem}'"]
    return profile, problems


_CACHE: dict[str, Profile] = {}


def load_profile(name_or_path: str | Path) -> Profile:
    """Load a built-in profile by id, or a profile file by path; raise ProfileError if broken."""
    key = str(name_or_path)
    if key in _CACHE:
        return _CACHE[key]
    path = Path(key)
    # A bare name is a built-in profile id; a path names a file (even a missing one, for a clear error).
    if path.suffix not in (".yaml", ".yml") and "/" not in key and "\\" not in key:
        path = builtin_dir() / f"{key.lower()}.yaml"
        if not path.exists():
            known = ", ".join(builtin_ids())
            raise ProfileError(f"unknown profile '{key}' (built-in: {known}; or give a path to a .yaml file)")
    profile, problems = read_profile(path)
    if profile is None:
        more = f" (and {len(problems) - 1} more; run 'servotool profiles check {path}')" if len(problems) > 1 else ""
        raise ProfileError(f"broken profile: {problems[0]}{more}")
    _CACHE[key] = profile
    return profile
