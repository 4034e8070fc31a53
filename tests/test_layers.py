"""The package's structure: no import cycle, imports only go down the layers, and the simulator stands without the
client side. Imports are read from the source (module level and inside functions alike), so an import hidden in a
function cannot close a cycle unnoticed."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "servotool"

# Lowest first: a module imports only from its own layer and those below.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("servotool", "servotool.errors", "servotool.clock", "servotool.files", "servotool.words"),
    ("servotool.model",),
    ("servotool.link",),
    ("servotool.connection",),  # option layering: pure data over the model and port parsing (plans use it too)
    ("servotool.drive",),
    ("servotool.ops",),
    ("servotool.motion",),
    ("servotool.tuning",),
    ("servotool.report",),  # pictures of measurements and tune results (plan steps write tune reports)
    ("servotool.commission",),
    ("servotool.session",),
    ("servotool.fleet",),  # many buses at once, a worker each, on sessions (issue 35)
    ("servotool.cli", "servotool.__main__"),
)
# Known upward imports still to be removed, each with why it exists.
UPWARD_EXCEPTIONS: dict[tuple[str, str], str] = {}
# The simulator is a side branch: it imports only the model, errors, clock, files, port parsing and the CRC, and
# only the session and the CLI import it.
SIM = "servotool.sim"
SIM_MAY_IMPORT = (*LAYERS[0], "servotool.model", "servotool.link.ports", "servotool.link.crc", SIM)
SIM_IMPORTED_BY = ("servotool.session", "servotool.cli", SIM)
CLIENT_SIDE = (
    "servotool.link.master",
    "servotool.drive",
    "servotool.ops",
    "servotool.motion",
    "servotool.tuning",
    "servotool.report",
    "servotool.commission",
    "servotool.connection",
    "servotool.session",
    "servotool.cli",
    "pymodbus.client",
)
# tuning's pure rooms: the fit (a log in, an estimate out) and the control (gains and margins) import numpy, the
# standard library, the model and their own room only, so they run on any log without a drive.
PURE_ROOMS = ("servotool.tuning.fit", "servotool.tuning.control")
PURE_MAY_IMPORT = ("__future__", "numpy", "servotool.model")


def modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its own name)."""
    out = {}
    for path in (ROOT / PACKAGE).rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def imported(name: str, path: Path, known: dict[str, Path]) -> set[str]:
    """The package's modules one module imports, anywhere in its source."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            # `from pkg import mod` imports pkg.mod; `from mod import name` imports mod
            found.update(f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names)
    return {m for m in found if m in known and m != name}


def imported_anything(name: str, path: Path) -> set[str]:
    """Every module one module imports, anywhere in its source, by absolute dotted name (the package's or not)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
            found.add(base)
    return found


def impure_imports(name: str, path: Path, room: str) -> list[str]:
    """What a module of a pure room imports beyond numpy, the standard library, the model and its own room."""
    return sorted(
        m
        for m in imported_anything(name, path)
        if m.split(".")[0] not in sys.stdlib_module_names and not any(within(m, p) for p in (*PURE_MAY_IMPORT, room))
    )


def import_graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imported(name, path, known) for name, path in known.items()}


def within(module: str, prefix: str) -> bool:
    if prefix == PACKAGE:
        return module == PACKAGE
    return module == prefix or module.startswith(prefix + ".")


def layer_of(module: str) -> int | None:
    for rank, prefixes in enumerate(LAYERS):
        if any(within(module, p) for p in prefixes):
            return rank
    return None


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a path that returns to its start, or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state and (cycle := visit(nxt)):
                return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (cycle := visit(start)):
            return cycle
    return None


def test_the_cycle_finder_finds_a_cycle_closed_inside_a_function(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from pkg.b import thing\n")
    (pkg / "b.py").write_text("thing = 1\n\ndef later():\n    from pkg import a\n    return a\n")
    (pkg / "c.py").write_text("from . import b\n")
    known = {f"pkg.{p.stem}": p for p in pkg.glob("[abc].py")}
    graph = {name: imported(name, path, known) for name, path in known.items()}
    assert graph == {"pkg.a": {"pkg.b"}, "pkg.b": {"pkg.a"}, "pkg.c": {"pkg.b"}}
    assert find_cycle(graph) == ["pkg.a", "pkg.b", "pkg.a"]
    assert find_cycle({"pkg.a": {"pkg.b"}, "pkg.b": set(), "pkg.c": {"pkg.b"}}) is None


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_every_module_belongs_to_a_layer():
    unplaced = [m for m in import_graph() if layer_of(m) is None and not within(m, SIM)]
    assert not unplaced, f"add these modules to a layer in {Path(__file__).name}: {unplaced}"


def test_imports_go_only_down_the_layers():
    upward = []
    for module, targets in import_graph().items():
        rank = layer_of(module)
        for target in targets:
            target_rank = layer_of(target)
            if (
                rank is not None
                and target_rank is not None
                and target_rank > rank
                and (module, target) not in UPWARD_EXCEPTIONS
            ):
                upward.append(f"{module} imports {target}")
    assert not upward, upward


def test_the_purity_check_sees_a_procedure_or_a_library_imported_in_a_function(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "import math\nimport numpy as np\nfrom servotool.model.profile import Profile\nfrom . import signals\n\n"
        "def later():\n    import yaml\n    from servotool.drive import Drive\n"
    )
    found = impure_imports("servotool.tuning.fit.m", module, "servotool.tuning.fit")
    assert found == ["servotool.drive", "yaml"]


@pytest.mark.parametrize("room", PURE_ROOMS)
def test_tunings_pure_rooms_import_only_numpy_the_standard_library_and_the_model(room):
    rooms = [(name, path) for name, path in modules().items() if within(name, room)]
    assert rooms, f"{room} has no modules"
    wrong = {name: found for name, path in rooms if (found := impure_imports(name, path, room))}
    assert not wrong, wrong


def test_the_simulator_imports_only_what_it_may_and_only_session_and_cli_import_it():
    wrong = []
    for module, targets in import_graph().items():
        for target in targets:
            if within(module, SIM) and not any(within(target, p) for p in SIM_MAY_IMPORT):
                wrong.append(f"{module} imports {target}")
            if within(target, SIM) and not any(within(module, p) for p in SIM_IMPORTED_BY):
                wrong.append(f"{module} imports {target}")
    assert not wrong, wrong


@pytest.mark.parametrize("module", ["servotool.sim.server", "servotool.sim.virtual"])
def test_the_simulator_loads_without_the_client_side(module):
    probe = f"import sys, {module}\nprint('\\n'.join(sorted(sys.modules)))"
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 0, proc.stderr
    loaded = proc.stdout.split()
    assert module in loaded
    assert not [m for m in loaded if any(within(m, c) for c in CLIENT_SIDE)]
