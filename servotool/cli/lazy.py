"""Command groups whose sub-commands are imported when called: `servotool param get` does not load numpy for
`tune`, nor any other command's module.

A sub-command is registered by name as "module:attribute" (a typer app, or a command function) with its one-line
help, which `servotool --help` lists without importing anything; several targets under one name are merged into one
group (`param` is the values app and the files app). Completion, which asks each sub-command for its help, imports
them all; commands registered the usual typer way still work beside these.

Every command built here prints its help as plain text (typer's rich_markup_mode=None: rich's help panels load
markdown and pygments, ~3x a bare start) and ends it with its examples (cli/examples.py).
"""

from __future__ import annotations

import copy
import importlib
from difflib import get_close_matches
from typing import Any, ClassVar, NamedTuple

import typer
from typer.core import TyperGroup

from servotool.cli import examples


class Lazy(NamedTuple):
    """One sub-command: where it lives, and its one line of help (also the whole help of a merged group)."""

    targets: tuple[str, ...]
    help: str | None


def lazy(*targets: str, help: str | None = None) -> Lazy:
    """A sub-command by "module:attribute"; `help` is what `servotool --help` lists (the help of a group made of
    several targets). Without it, --help imports the command to ask (tests/cli/test_examples.py wants it given)."""
    return Lazy(targets, help)


def _load(target: str) -> Any:
    module, _, attribute = target.partition(":")
    return getattr(importlib.import_module(module), attribute)


def build(name: str, spec: Lazy) -> Any:
    """The click command for a registry entry (imports its modules; a group's sub-commands are built when
    called)."""
    objects = [_load(t) for t in spec.targets]
    if len(objects) == 1 and not isinstance(objects[0], typer.Typer):
        # completion is the root's: not on each command's help
        single = typer.Typer(add_completion=False, rich_markup_mode=None)
        single.command(name, epilog=examples.epilog(name))(objects[0])
        command = typer.main.get_command(single)
    else:
        command = _app_group(objects, name)
    command.name = name
    if spec.help is not None:
        command.short_help = spec.help  # as `servotool --help` lists it before anything is imported
        if len(spec.targets) > 1:  # a merged group has no help of its own
            command.help = spec.help
    if hasattr(command, "commands") and not command.invoke_without_command:
        command.no_args_is_help = True  # a bare group name shows its help, once
    return command


def _app_group(apps: list[typer.Typer], name: str) -> Any:
    """One group of the typer apps' commands, each built (typer reads its signature) only when asked for; an app
    with sub-groups of its own is built whole, the usual typer way (its help then as the app declares it)."""
    if any(a.registered_groups for a in apps):
        group = typer.main.get_group(apps[0])
        for extra in apps[1:]:
            for sub_name, sub in typer.main.get_group(extra).commands.items():
                group.add_command(sub, sub_name)
        return group
    infos = {
        (i.name or typer.main.get_command_name(i.callback.__name__)): (i, a)
        for a in apps
        for i in a.registered_commands
        if i.callback is not None
    }
    shell = copy.copy(apps[0])
    shell.registered_commands = []
    shell.rich_markup_mode = None
    shell.info = copy.copy(apps[0].info)
    shell.info.cls = _OnDemand
    group = typer.main.get_group(shell)
    group.infos = infos
    group.path = name
    return group


class _Suggesting(TyperGroup):
    """A group that answers an unknown sub-command with the close ones, lazily registered ones included (typer's
    own suggestion sees only the commands built so far)."""

    def resolve_command(self, ctx: Any, args: list[str]) -> Any:
        if args and not args[0].startswith("-") and not ctx.resilient_parsing:
            names = self.list_commands(ctx)
            if args[0] not in names and (close := get_close_matches(args[0], names)):
                ctx.fail(f"No such command {args[0]!r}. Did you mean {', '.join(map(repr, close))}?")
        return super().resolve_command(ctx, args)


class _OnDemand(_Suggesting):
    """A typer group whose commands are made from their CommandInfo on first use."""

    infos: dict[str, tuple[Any, typer.Typer]]
    path = ""  # the group's name on the command line ('param')

    def list_commands(self, ctx: Any) -> list[str]:
        return [*super().list_commands(ctx), *(n for n in getattr(self, "infos", {}) if n not in self.commands)]

    def get_command(self, ctx: Any, cmd_name: str) -> Any:
        found = getattr(self, "infos", {}).get(cmd_name)
        if cmd_name not in self.commands and found is not None:
            info, app = found
            if (more := examples.epilog(f"{self.path} {cmd_name}")) is not None:
                info = copy.copy(info)
                info.epilog = f"{info.epilog}\n\n{more}" if info.epilog else more
            self.commands[cmd_name] = typer.main.get_command_from_info(
                info, pretty_exceptions_short=app.pretty_exceptions_short, rich_markup_mode=None
            )
        return super().get_command(ctx, cmd_name)


def lazy_group(commands: dict[str, Lazy]) -> type[TyperGroup]:
    """A TyperGroup class (for typer.Typer(cls=...)) that also offers these lazily imported sub-commands."""

    class LazyGroup(_Suggesting):
        registry: ClassVar[dict[str, Lazy]] = commands

        def list_commands(self, ctx: Any) -> list[str]:
            return [*super().list_commands(ctx), *(n for n in self.registry if n not in self.commands)]

        def get_command(self, ctx: Any, cmd_name: str) -> Any:
            if cmd_name not in self.commands and cmd_name in self.registry:
                self.commands[cmd_name] = build(cmd_name, self.registry[cmd_name])
            return super().get_command(ctx, cmd_name)

        def format_commands(self, ctx: Any, formatter: Any) -> None:
            """The commands and their one-line help, from the registry for those not loaded."""
            rows = []
            for name in self.list_commands(ctx):
                if name not in self.commands and (known := self.registry[name].help) is not None:
                    rows.append((name, known))
                elif not (command := self.get_command(ctx, name)).hidden:
                    rows.append((name, command.get_short_help_str(formatter.width)))
            if rows:
                with formatter.section("Commands"):
                    formatter.write_dl(rows)

    return LazyGroup
