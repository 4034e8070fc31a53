"""Loading profiles: built-in ids and files, parsed and validated once per process.

A parsed profile is also kept in the user cache folder as JSON (servotool.model.compiled), keyed by the file's
content and the model code that parsed it, so that the next process loads it in a few milliseconds instead of
parsing the YAML. Nothing in that folder is ever run: the file is data, carries a SHA-256 of its body, and is used
only when the hash, the key and (on POSIX) its owner match; anything else is rebuilt from the YAML.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from functools import cache
from pathlib import Path

from servotool import __version__
from servotool.errors import FileProblem, ProfileError, UnknownName
from servotool.files import cache_dir, parse_yaml, read_text, write_atomic
from servotool.model.lookup import suggest
from servotool.model.profile import Profile

CACHE_FORMAT = "servotool-compiled-profile/1"
CACHE_SUFFIX = ".json"


def builtin_dir() -> Path:
    """Folder of the profiles shipped with the package (or, in a source checkout, the top-level profiles/)."""
    here = Path(__file__).resolve().parent.parent  # the servotool package
    installed = here / "profiles"
    return installed if installed.is_dir() else here.parent / "profiles"


def builtin_ids() -> list[str]:
    return sorted(p.stem for p in builtin_dir().glob("*.yaml"))


class UnknownProfile(UnknownName, ProfileError):
    """No built-in profile by that id (a path to a .yaml file also works)."""


@cache
def _code_stamp() -> bytes:
    """What a compiled profile depends on besides its file: this code (the model package) and the Python."""
    digest = hashlib.sha256(f"{__version__} {sys.version_info[:2]}".encode())
    here = Path(__file__).parent
    for name in sorted(n for n in os.listdir(here) if n.endswith(".py")):  # no glob: its regex costs 10 ms
        digest.update((here / name).read_bytes())
    return digest.digest()


def _cache_key(path: Path, text: str) -> str:
    """What a compiled profile was made from: this model code, the file's place and its text."""
    return hashlib.sha256(_code_stamp() + str(path.resolve()).encode() + b"\0" + text.encode()).hexdigest()


def _cache_file(key: str, path: Path) -> Path:
    return cache_dir() / "profiles" / f"{path.stem}-{key[:32]}{CACHE_SUFFIX}"


def _cached(where: Path, key: str) -> tuple[Profile | None, list[str]] | None:
    """The compiled profile in the cache file, or None: missing, damaged, edited (its body no longer matches its
    hash), made from another file or code (its key), or not owned by this user (root, with a user's HOME, does
    not take the user's files for its own)."""
    from servotool.model.compiled import from_data

    try:
        with where.open("rb") as fh:
            st = os.fstat(fh.fileno())
            if os.name == "posix" and (st.st_uid != os.geteuid() or st.st_mode & 0o022):
                return None
            head, _, body = fh.read().partition(b"\n")
        header = json.loads(head)
        if (
            not isinstance(header, dict)
            or header.get("format") != CACHE_FORMAT
            or header.get("key") != key
            or header.get("sha256") != hashlib.sha256(body).hexdigest()
        ):
            return None
        return from_data(json.loads(body))
    except (OSError, ValueError):  # a damaged or foreign cache file is rebuilt, never trusted
        return None


def _store(where: Path, key: str, parsed: tuple[Profile | None, list[str]]) -> None:
    """Keep the compiled profile (replacing those of older versions of the file, and any pickle the cache held
    before it was JSON); a cache that cannot be written is no error."""
    from servotool.model.compiled import to_data

    body = json.dumps(to_data(parsed), ensure_ascii=False, separators=(",", ":")).encode()
    header = {"format": CACHE_FORMAT, "key": key, "sha256": hashlib.sha256(body).hexdigest()}
    try:
        stem = where.name.rsplit("-", 1)[0] + "-"
        for old in os.listdir(where.parent) if where.parent.is_dir() else []:
            if old.startswith(stem) and old.endswith((CACHE_SUFFIX, ".pickle")):
                (where.parent / old).unlink(missing_ok=True)
        write_atomic(where, json.dumps(header).encode() + b"\n" + body, durable=False)
    except OSError:
        pass


def _parse(path: Path) -> tuple[Profile | None, list[str]]:
    """The profile in a file and its problems, from the compiled cache when the file has not changed."""
    try:
        text = read_text(path)
    except FileProblem as exc:
        return None, [str(exc)]
    key = _cache_key(path, text)
    where = _cache_file(key, path)
    if (hit := _cached(where, key)) is not None:
        return hit
    try:
        data = parse_yaml(text, path)
    except FileProblem as exc:
        return None, [str(exc)]
    from servotool.model.schema import parse_profile  # the parser only when the cache has not the profile

    parsed = parse_profile(data, str(path))
    _store(where, key, parsed)
    return parsed


def read_profile(path: Path) -> tuple[Profile | None, list[str]]:
    """Parse a profile file; return it (or None) and the list of problems."""
    profile, problems = _parse(path)
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
            raise UnknownProfile("profile", key, None, suggest(key, builtin_ids()), builtin_ids())
    profile, problems = read_profile(path)
    if profile is None:
        more = f" (and {len(problems) - 1} more; run 'servotool profiles check {path}')" if len(problems) > 1 else ""
        raise ProfileError(f"broken profile: {problems[0]}{more}")
    _CACHE[key] = profile
    return profile
