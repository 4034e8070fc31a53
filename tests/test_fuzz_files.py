"""Bad files never crash servotool (issue 14 defect 8): a few hundred seeded mutants of each file kind (profile,
backup, plan, config) go through the library loaders in-process, a handful through the command line. Each is
accepted (a mutation can leave a file valid) or refused with one line; never a traceback, internal error or signal.
"""

from __future__ import annotations

import os
import random
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from servotool.commission.plan import load_plan
from servotool.commission.steps import validate
from servotool.connection import ConnectOptions, resolve
from servotool.errors import ServoError
from servotool.model.loader import builtin_dir, load_profile
from servotool.ops import backup

ROOT = Path(__file__).resolve().parent.parent
MUTANTS = 200
VALUES = [
    "[1, 2]",
    "{a: 1}",
    "true",
    "null",
    "''",
    "-1",
    "1e309",
    "-1e309",
    ".nan",
    ".inf",
    "-.inf",
    "1e-300",
    "99999999999999999999999999",
    "!!binary aGVsbG8=",
    "!!timestamp 2001-12-14",
    "!!python/object:os.system x",
    "!!set {a, b}",
    "0x10",
    "٣",
    "５",
    "&a [*a]",
    "!!float 1",
    "3.7",
    '"\\x00"',
    "*nothing",
]

PLAN = """\
port: sim
profile: dsx7e
units: [1, 2]
retries: 1
steps:
  - set: {Pn101: 25.0, Pn512: 150}
  - expect: {Pn101: {value: 25.0, tol: 0.5}, Un100: {min: -1, max: 1}}
  - set: {Pn102: 30.0}
    unit: 2
  - tune inertia: {rigidity: 12, travel: 1.0}
  - jog: {speed: 300, time: 0.5, max_travel: 5}
  - backup: {file: axis-{unit}.yaml, overwrite: true}
  - wait: 0.5
  - save:
  - prompt: Is the machine clear?
"""

CONFIG = "port: sim\nprofile: dsx7e\nunit: 1\nbaud: 19200\nparity: E\nstopbits: 1\ntimeout: 0.5\nretries: 2\n"


def _backup_text() -> str:
    p = load_profile("dsx7e")
    values = backup.defaults(p)
    b = backup.Backup(p.id, p.version, p.model, 1, "2026-01-01T00:00:00+00:00", "0", {}, values)
    return b.to_yaml(p)


def mutate(text: str, rng: random.Random) -> bytes:
    """One mutant: byte flips, a truncation, a wrong-typed value, deep nesting, a tag, or bytes not UTF-8."""
    data = text.encode()
    kind = rng.randrange(7)
    if kind == 0:  # byte flips
        b = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)
    if kind == 1:  # truncation
        return data[: rng.randrange(len(data))]
    lines = text.splitlines(keepends=True)
    i = rng.randrange(len(lines))
    key, sep, _ = lines[i].partition(": ")
    if kind == 2 and sep:  # a wrong type, NaN/inf, a huge number, a tag
        lines[i] = f"{key}: {rng.choice(VALUES)}\n"
    elif kind == 3:  # deep nesting, flow or block
        depth = rng.choice([40, 1000, 100_000])
        deep = (
            "[" * depth + "]" * depth
            if rng.random() < 0.5
            else "".join(f"{' ' * d}k:\n" for d in range(min(depth, 3000))) + " " * min(depth, 3000) + "x\n"
        )
        lines[i] = f"{key}: {deep}\n" if sep and deep.startswith("[") else deep
    elif kind == 4:  # not UTF-8
        return data[: len(data) // 2] + bytes([rng.choice([0xFF, 0xFE, 0xC0, 0x80])]) + data[len(data) // 2 :]
    elif kind == 5 and sep:  # unknown key beside a known one
        lines.insert(i, f"{key}_x{rng.randrange(99)}: 1\n")
    else:  # a whole line duplicated or dropped
        if rng.random() < 0.5:
            lines.insert(i, lines[i])
        else:
            del lines[i]
    return "".join(lines).encode()


def _profile(path: Path) -> None:
    load_profile(path)


def _backup(path: Path) -> None:
    backup.load(path, load_profile("dsx7e"))


def _plan(path: Path) -> None:
    validate(load_plan(path), load_profile("dsx7e"))


def _config(path: Path) -> None:
    os.environ["SERVOTOOL_CONFIG"] = str(path)
    resolve(ConnectOptions())


KINDS: dict[str, tuple[Callable[[], str], Callable[[Path], None]]] = {
    "profile": (lambda: (builtin_dir() / "sdc.yaml").read_text(), _profile),
    "backup": (_backup_text, _backup),
    "plan": (lambda: PLAN, _plan),
    "config": (lambda: CONFIG, _config),
}


@pytest.mark.parametrize("kind", list(KINDS))
def test_mutated_files_are_accepted_or_refused_in_one_line(kind, tmp_path, monkeypatch):
    monkeypatch.setenv("SERVOTOOL_CONFIG", str(tmp_path / "none.yaml"))
    make, load = KINDS[kind]
    text, rng = make(), random.Random(f"{kind}-14")
    refused = 0
    for n in range(MUTANTS):
        path = tmp_path / f"m{n}" / ("sdc.yaml" if kind == "profile" else f"{kind}.yaml")
        path.parent.mkdir()
        path.write_bytes(mutate(text, rng))
        try:
            load(path)
        except ServoError as exc:
            refused += 1
            msg = str(exc)
            assert msg and "\n" not in msg.strip() and "Traceback" not in msg, (n, msg)
            assert "internal error" not in msg, (n, msg)
        except Exception as exc:
            pytest.fail(f"{kind} mutant {n} ({path.read_bytes()[:200]!r}...): {type(exc).__name__}: {exc}")
    assert refused > MUTANTS // 3  # the mutations do break files (else the test proves nothing)


def test_bad_files_through_the_command_line_are_one_line_and_exit_2(tmp_path):
    deep = "[" * 100_000 + "]" * 100_000
    bad = tmp_path / "sdc.yaml"
    bad.write_text((builtin_dir() / "sdc.yaml").read_text().replace("model: SDC", f"model: {deep}", 1))
    plan = tmp_path / "plan.yaml"
    plan.write_text(f"port: sim\nsteps:\n  - set: {deep}\n")
    config = tmp_path / "config.yaml"
    config.write_text("port: sim\nretries: -.inf\n")
    env = {
        **os.environ,
        "SERVOTOOL_SIM_DIR": str(tmp_path / "sim"),
        "SERVOTOOL_BACKUP_DIR": str(tmp_path / "b"),
        "SERVOTOOL_CONFIG": str(tmp_path / "none.yaml"),
    }
    for args, extra in (
        (["profiles", "check", str(bad)], {}),
        (["run", str(plan), "--dry-run"], {}),
        (["--port", "sim", "param", "restore", str(plan), "--dry-run"], {}),
        (["--port", "sim", "param", "get", "Pn100"], {"SERVOTOOL_CONFIG": str(config)}),
    ):
        r = subprocess.run(
            [sys.executable, "-m", "servotool", *args],
            capture_output=True,
            text=True,
            cwd=ROOT,
            env={**env, **extra},
            timeout=60,
        )
        lines = [x for x in r.stderr.splitlines() if x.strip() and "SIMULATED" not in x]
        assert r.returncode in (1, 2) and len(lines) <= 2, (args, r.returncode, r.stderr[-2000:])
        assert "Traceback" not in r.stderr and "internal error" not in r.stderr, (args, r.stderr[-2000:])


@pytest.mark.parametrize("value", ["٣", "５", "1_0", "3.7", "-.inf", ".nan", "99"])
def test_config_numbers_are_plain_finite_whole_and_bounded(value, tmp_path, monkeypatch):
    config = tmp_path / "config.yaml"
    config.write_text(
        f"port: sim\nretries: {value!r}\n" if not value.startswith((".", "-.")) else f"port: sim\nretries: {value}\n"
    )
    monkeypatch.setenv("SERVOTOOL_CONFIG", str(config))
    with pytest.raises(ServoError, match="retries must be"):
        resolve(ConnectOptions())


@pytest.mark.parametrize("text", ["Pn101=٣", "Pn101=５", "Pn101=1_0"])
def test_values_take_ascii_digits_only(text):
    from servotool.drive import Drive

    d = Drive(None, load_profile("dsx7e"), 1)  # type: ignore[arg-type]  # parsing sends nothing
    with pytest.raises(ServoError, match="is not a number"):
        d.parse_assignment(text)
