"""Global options anywhere on the command line: `servotool param get Pn004 --port sim` as well as
`servotool --port sim param get Pn004`.

The global options are the root command's own (whatever main() declares, so an option added there is covered);
those found after the sub-command are moved in front of it, unless the sub-command has an option of the same name
(`sim serve --port` keeps its own). An option's value that looks like an option (`--csv --json`) is refused.
"""

from __future__ import annotations

from typing import Any

from servotool.errors import UsageError


def _options(command: Any) -> dict[str, bool]:
    """A command's option names -> whether the option takes a value."""
    names: dict[str, bool] = {}
    for p in getattr(command, "params", []):
        if getattr(p, "param_type_name", "") != "option":
            continue
        takes = not (getattr(p, "is_flag", False) or getattr(p, "count", False))
        for name in [*p.opts, *p.secondary_opts]:
            names[name] = takes
    return names


def _globals(root: Any) -> dict[str, bool]:
    eager = {n for p in root.params if getattr(p, "is_eager", False) for n in [*p.opts, *p.secondary_opts]}
    return {n: v for n, v in _options(root).items() if n not in eager}


def _leaf(root: Any, args: list[str], known: dict[str, bool]) -> tuple[Any, int]:
    """The sub-command the arguments name (loading it), and the index of the first argument after its name."""
    command, i = root, 0
    while i < len(args) and hasattr(command, "get_command"):
        token = args[i]
        if token == "--":
            break
        if token.startswith("-"):
            i += 2 if known.get(token.split("=", 1)[0]) and "=" not in token else 1
            continue
        sub = command.get_command(None, token)
        if sub is None:
            break
        command, i, known = sub, i + 1, _options(sub)
    return command, i


def hoist_globals(root: Any, args: list[str]) -> list[str]:
    """The arguments with the global options given after the sub-command moved in front of it."""
    glob = _globals(root)
    try:
        leaf, start = _leaf(root, args, glob)
    except Exception:  # a broken sub-command is reported when it runs, with the arguments as given
        return args
    own = _options(leaf)
    _refuse_missing_values(args, start, glob, {**glob, **own})
    if leaf is root:
        return args
    moved: list[str] = []
    # A flag of the sub-command given to its group (`alarm --json show`) or before it (`servotool --json param get
    # Pn004`) goes to the sub-command.
    values = _value_positions(args[:start], glob)
    between = [k for k in range(start) if own.get(args[k]) is False and args[k] not in glob and k not in values]
    rest = [a for k, a in enumerate(args[:start]) if k not in between] + [args[k] for k in between]
    i = start
    while i < len(args):
        token = args[i]
        if token == "--":
            rest += args[i:]
            break
        name = token.split("=", 1)[0]
        if name in glob and name not in own:
            takes = glob[name] and "=" not in token
            moved += args[i : i + 1 + takes]
            i += 1 + takes
            continue
        if _short_flags(token, glob, own):
            moved.append(token)
        else:
            rest.append(token)
            if own.get(name) and "=" not in token and i + 1 < len(args):
                rest.append(args[i + 1])  # an option's value is never taken for an option
                i += 1
        i += 1
    return moved + rest


def _refuse_missing_values(args: list[str], start: int, before: dict[str, bool], after: dict[str, bool]) -> None:
    """`monitor --csv --json` would log to a file named '--json': an option's value that looks like an option was
    left out, and is refused before anything runs."""
    for k, token in enumerate(args[:-1]):
        if token == "--":
            return
        known = before if k < start else after
        if known.get(token) and args[k + 1].startswith("--"):
            raise UsageError(f"{args[k + 1]!r} looks like an option, not a value for {token}: give the value after it")


def _value_positions(args: list[str], glob: dict[str, bool]) -> set[int]:
    """Where the values of global options are (`--port --json` would be a port named '--json', not a flag)."""
    return {k + 1 for k, token in enumerate(args) if glob.get(token) and "=" not in token}


def _short_flags(token: str, glob: dict[str, bool], own: dict[str, bool]) -> bool:
    """-vv, -qv: a cluster of global flags."""
    if not token.startswith("-") or token.startswith("--") or len(token) < 3:
        return False
    flags = [f"-{c}" for c in token[1:]]
    return all(f in glob and not glob[f] and f not in own for f in flags)
