"""Tab completion in `servotool shell`: the app's own command tree walked as click parses it, and each parameter's
own completer (cli.complete: codes and names of the open profile's entries, groups, profile ids)."""

from __future__ import annotations

import shlex
from collections.abc import Iterable
from typing import Any

import typer
from prompt_toolkit.completion import CompleteEvent, Completer, Completion
from prompt_toolkit.document import Document


def candidates(root: Any, root_args: list[str], words: list[str], incomplete: str) -> list[tuple[str, str]]:
    """(value, help) for the word being typed after `words`: a sub-command, an option, or a parameter's value.
    `root_args` are root options the completers need (the open profile)."""
    ctx = root.make_context("servotool", list(root_args), resilient_parsing=True)
    command, waiting = root, None
    for word in words:
        if waiting is not None:  # the value of the option before
            waiting = None
            continue
        if word.startswith("-"):
            option = _option(command, root, word)
            takes_value = option is not None and not getattr(option, "is_flag", False) and not option.count
            waiting = option if takes_value and "=" not in word else None
            continue
        sub = command.get_command(ctx, word) if hasattr(command, "list_commands") else None
        if sub is not None:
            ctx = sub.make_context(word, [], parent=ctx, resilient_parsing=True)
            command = sub
    if waiting is not None:
        return _values(waiting, ctx, incomplete)
    if incomplete.startswith("-"):
        params = [*command.params, *(root.params if command is not root else ())]
        found = {o: p.help or "" for p in params for o in (*p.opts, *p.secondary_opts) if o.startswith(incomplete)}
        return sorted(found.items())
    if hasattr(command, "list_commands"):
        return [(name, "") for name in command.list_commands(ctx) if name.startswith(incomplete)]
    for param in command.params:
        if getattr(param, "param_type_name", "") == "argument":
            return _values(param, ctx, incomplete)
    return []


def _values(param: Any, ctx: Any, incomplete: str) -> list[tuple[str, str]]:
    """A parameter's own completions of what was typed; where none starts with it, those whose help holds it (a
    code's help is its entry's name: 'inertia' offers the inertia entries)."""
    found = _items(param.shell_complete(ctx, incomplete))
    if found or len(incomplete) < 3:
        return found
    typed = incomplete.lower()
    return [(value, meta) for value, meta in _items(param.shell_complete(ctx, "")) if typed in meta.lower()]


def _option(command: Any, root: Any, word: str) -> Any:
    name = word.split("=", 1)[0]
    for params in (command.params, root.params):
        for p in params:
            if name in (*p.opts, *p.secondary_opts):
                return p
    return None


def _items(items: Iterable[Any]) -> list[tuple[str, str]]:
    return [(str(i.value), i.help or "") for i in items]


class CommandCompleter(Completer):
    """prompt_toolkit's side of `candidates`."""

    def __init__(self, root_args: list[str]) -> None:
        from servotool.cli.main import app

        self.root = typer.main.get_command(app)
        self.root_args = root_args

    def get_completions(self, document: Document, complete_event: CompleteEvent) -> Iterable[Completion]:
        text = document.text_before_cursor
        try:
            words = shlex.split(text)
        except ValueError:  # inside an open quote
            return
        incomplete = "" if not text or text[-1].isspace() else (words.pop() if words else "")
        if words[:1] == ["servotool"]:
            words = words[1:]
        try:
            found = candidates(self.root, self.root_args, words, incomplete)
        except Exception:  # completion must never break typing
            return
        for value, meta in found:
            yield Completion(value, start_position=-len(incomplete), display_meta=meta)
