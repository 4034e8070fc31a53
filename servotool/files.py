"""The files servotool keeps: user folders, atomic writes, YAML reading with one error format, a cross-process lock.

Folders come from platformdirs (XDG on Linux, so XDG_CONFIG_HOME, XDG_STATE_HOME and XDG_DATA_HOME apply there;
the usual places on Windows and macOS); SERVOTOOL_CONFIG, SERVOTOOL_SIM_DIR and SERVOTOOL_BACKUP_DIR override them
(and SERVOTOOL_CACHE_DIR the cache folder).
"""

from __future__ import annotations

import errno
import os
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import platformdirs

from servotool.clock import RealClock
from servotool.errors import FileProblem

APP = "servotool"


def _yaml() -> tuple[Any, Any]:
    """PyYAML and its safe loader (the C one when PyYAML has it: several times faster), imported when a YAML file
    is read: a command that reads none (a profile from the compiled cache) starts without it."""
    import yaml

    return yaml, getattr(yaml, "CSafeLoader", yaml.SafeLoader)


# Bounds checked before a document is built: the loaders recurse (a profile nested 100,000 deep crashed the C
# loader), and no servotool file comes near them (profiles are ~150 kB and ~8 levels deep).
MAX_YAML_BYTES = 4 << 20
MAX_YAML_DEPTH = 32

# A temporary file of a process that no longer runs is swept after this long where its pid cannot be checked.
STALE_TMP_S = 3600.0


# ----- user folders ----------------------------------------------------------------------------------------------


def config_file() -> Path:
    """The user's config file (SERVOTOOL_CONFIG, else config.yaml in the user config folder)."""
    if env := os.environ.get("SERVOTOOL_CONFIG"):
        return Path(env)
    return platformdirs.user_config_path(APP, appauthor=False) / "config.yaml"


def sim_state_dir() -> Path:
    """Where simulated drives keep their state (SERVOTOOL_SIM_DIR, else 'sim' in the user state folder)."""
    if env := os.environ.get("SERVOTOOL_SIM_DIR"):
        return Path(env)
    return platformdirs.user_state_path(APP, appauthor=False) / "sim"


def backup_dir() -> Path:
    """Where automatic backups go (SERVOTOOL_BACKUP_DIR, else 'backups' in the user data folder)."""
    if env := os.environ.get("SERVOTOOL_BACKUP_DIR"):
        return Path(env)
    return platformdirs.user_data_path(APP, appauthor=False) / "backups"


def shell_history_file() -> Path:
    """The lines typed in `servotool shell` (in the user state folder, beside the simulated drives)."""
    return platformdirs.user_state_path(APP, appauthor=False) / "shell-history"


def cache_dir() -> Path:
    """Where servotool keeps what it can rebuild (SERVOTOOL_CACHE_DIR, else the user cache folder)."""
    if env := os.environ.get("SERVOTOOL_CACHE_DIR"):
        return Path(env)
    return platformdirs.user_cache_path(APP, appauthor=False)


# ----- writing ---------------------------------------------------------------------------------------------------


def write_atomic(path: Path, text: str | bytes, *, replace: bool = True, durable: bool = True) -> os.stat_result:
    """Write text (UTF-8) or bytes so that readers see the old file or the new one, never half of one.

    The file is made as a private temporary file beside the target (mode 0600) and renamed over it. With
    replace=False an existing file is never replaced, not even one that appears meanwhile: FileExistsError.
    durable=False skips the fsync (for state rewritten many times a second). Returns the new file's stat.
    Other failures are OSError, for the caller to word.

    A target that exists and is no regular file (/dev/null, /dev/stdout, a FIFO, a terminal) is written through,
    not renamed over: renaming a file over /dev/null, as root, would replace the device for every program.
    """
    try:
        found = path.stat()
    except (FileNotFoundError, NotADirectoryError):
        found = None
    if found is not None and not stat.S_ISREG(found.st_mode) and not stat.S_ISDIR(found.st_mode):
        if not replace:
            raise FileExistsError(errno.EEXIST, "exists", str(path))
        with open(path, "wb") if isinstance(text, bytes) else open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
            return os.fstat(fh.fileno())
    path.parent.mkdir(parents=True, exist_ok=True)
    import tempfile

    sweep_temp(path.parent, path.name)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.{os.getpid()}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") if isinstance(text, bytes) else os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            if durable:
                os.fsync(fh.fileno())
            st = os.fstat(fh.fileno())
        if replace and os.name == "posix":
            try:  # a replaced file keeps its mode (a user's 0644 backup stays readable by others)
                os.chmod(tmp, path.stat().st_mode & 0o7777)
            except FileNotFoundError:
                pass
        if replace:
            os.replace(tmp, path)
        else:
            os.link(tmp, path)  # fails if the name exists, even one that appeared since the caller looked
    finally:
        Path(tmp).unlink(missing_ok=True)
    return st


def process_alive(pid: int) -> bool | None:
    """Whether a process of this host runs; None where that cannot be told."""
    if pid <= 0:
        return None
    if os.name == "nt":
        return _windows_process_alive(pid)
    try:
        os.kill(pid, 0)  # signal 0: only asks (on Windows os.kill would terminate it)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # exists, owned by someone else
    return True


def _windows_process_alive(pid: int) -> bool | None:
    """OpenProcess and GetExitCodeProcess (kernel32): still running while the exit code is STILL_ACTIVE."""
    try:
        import ctypes

        kernel32 = ctypes.windll.kernel32  # type: ignore[attr-defined]
        handle = kernel32.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
        if not handle:
            return False if kernel32.GetLastError() == 87 else None  # ERROR_INVALID_PARAMETER: no such pid
        try:
            code = ctypes.c_ulong()
            if not kernel32.GetExitCodeProcess(handle, ctypes.byref(code)):
                return None
            return code.value == 259  # STILL_ACTIVE
        finally:
            kernel32.CloseHandle(handle)
    except (AttributeError, OSError):
        return None


def sweep_temp(folder: Path, name: str = "") -> int:
    """Delete the temporary files write_atomic left in folder (for the target `name`, or all) when the process
    that made them is gone (a kill -9 between write and rename). Returns how many were removed."""
    removed = 0
    try:  # a plain listing: pathlib's glob compiles a pattern each time (3 folders at each command's start)
        with os.scandir(folder) as listing:
            candidates = [folder / e.name for e in listing if e.name.startswith(f".{name}") and e.name.endswith(".tmp")]
    except OSError:
        return 0
    for tmp in candidates:
        pid_text = tmp.name[: -len(".tmp")].rsplit(".", 2)[-2] if tmp.name.count(".") >= 3 else ""
        alive = process_alive(int(pid_text)) if pid_text.isascii() and pid_text.isdigit() else None
        try:
            if alive is False or (alive is None and RealClock().wall() - tmp.stat().st_mtime > STALE_TMP_S):
                tmp.unlink()
                removed += 1
        except OSError:
            pass
    return removed


# ----- reading ---------------------------------------------------------------------------------------------------


def read_text(path: Path) -> str:
    """A text file's content; FileProblem when it cannot be read or is not UTF-8."""
    try:
        with path.open("rb") as fh:
            data = fh.read(MAX_YAML_BYTES + 1)
        if len(data) > MAX_YAML_BYTES:
            raise FileProblem(path, f"too large (more than {MAX_YAML_BYTES} bytes)")
        return data.decode("utf-8")
    except OSError as exc:
        raise FileProblem(path, f"cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError as exc:
        raise FileProblem(path, f"not UTF-8 text (byte {exc.start})") from None


def _yaml_problem(path: Path, exc: Any) -> FileProblem:
    mark = getattr(exc, "problem_mark", None)
    problem = " ".join(str(getattr(exc, "problem", None) or exc).split())  # one line, whatever the file held
    return FileProblem(path, f"invalid YAML: {problem}", line=mark.line + 1 if mark else None)


def check_yaml_bounds(text: str, path: Path) -> None:
    """Refuse, before anything is built, a document larger or deeper than any servotool file, or one with
    aliases (a recursive alias makes a structure that contains itself). Scanning events does not recurse."""
    if len(text) > MAX_YAML_BYTES:
        raise FileProblem(path, f"too large ({len(text)} characters; at most {MAX_YAML_BYTES})")
    yaml, loader = _yaml()
    depth = 0
    try:
        for event in yaml.parse(text, Loader=loader):
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > MAX_YAML_DEPTH:
                    raise FileProblem(
                        path,
                        f"nested more than {MAX_YAML_DEPTH} levels deep",
                        line=event.start_mark.line + 1 if event.start_mark else None,
                    )
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
            elif isinstance(event, yaml.AliasEvent):
                raise FileProblem(
                    path,
                    "YAML aliases (*name) are not accepted",
                    line=event.start_mark.line + 1 if event.start_mark else None,
                )
    except yaml.YAMLError as exc:
        raise _yaml_problem(path, exc) from None


def parse_yaml(text: str, path: Path) -> Any:
    """The data of a YAML document read from path; FileProblem (with the line) when it is not valid YAML."""
    return _read_yaml(text, path, "load")


def compose_yaml(text: str, path: Path) -> Any:
    """The node tree of a YAML document (for the line of each key); FileProblem when it is not valid YAML."""
    return _read_yaml(text, path, "compose")


def _read_yaml(text: str, path: Path, how: str) -> Any:
    check_yaml_bounds(text, path)
    yaml, loader = _yaml()
    try:
        return getattr(yaml, how)(text, Loader=loader)
    except yaml.YAMLError as exc:
        raise _yaml_problem(path, exc) from None


def load_yaml(path: Path) -> Any:
    """Read and parse a YAML file; every problem is one FileProblem: 'FILE: [line N: ]PROBLEM'."""
    return parse_yaml(read_text(path), path)


# ----- locking ---------------------------------------------------------------------------------------------------


class FileLock:
    """An exclusive lock between processes, on a lock file kept open for the holder's lifetime (opening it for
    each use costs a third of the simulator's request rate). Not reentrant. filelock's descriptor lock makes it
    flock on POSIX and LockFileEx on Windows."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fh: IO[str] | None = None

    @contextmanager
    def held(self, poll_interval: float = 0.001) -> Iterator[None]:
        # Imported here, where a lock is used: filelock takes 40 ms to import.
        from filelock import lock_descriptor, unlock_descriptor

        fd = self._open()
        lock_descriptor(fd, poll_interval=poll_interval)  # holders keep it for milliseconds: poll often
        try:
            yield
        finally:
            unlock_descriptor(fd)

    def try_acquire(self) -> bool:
        """Take the lock if nobody holds it (release() gives it back); False at once when another holder has it."""
        from filelock import lock_descriptor

        return bool(lock_descriptor(self._open(), blocking=False))

    def release(self) -> None:
        from filelock import unlock_descriptor

        if self._fh is not None:
            unlock_descriptor(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def _open(self) -> int:
        if self._fh is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fh = self.path.open("a", encoding="utf-8")
        return self._fh.fileno()
