"""Plain option values (str, int, float, bool, Path, lists of them) converted without pydantic.

typer 0.29 converts every option value through a pydantic TypeAdapter; importing pydantic and building the
adapters costs about as much as the rest of a one-shot command. Parameters with nothing but a plain type take this
short path; anything else (bounds, choices, a parser, path checks) still goes through typer's own. When typer's
internals are not the ones this was written for, nothing is changed: the CLI is only slower.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, get_args, get_origin

_TRUE = {"1", "true", "t", "yes", "y", "on"}
_FALSE = {"0", "false", "f", "no", "n", "off", ""}
_KIND = {int: "integer", float: "number", bool: "boolean"}


def _convert(kind: type, value: Any) -> Any:
    """One value of a plain type; ValueError with the sentence to show."""
    if isinstance(value, kind) and not (kind is int and isinstance(value, bool)):
        return value
    text = str(value).strip()
    if kind is bool:
        if text.lower() in _TRUE | _FALSE:
            return text.lower() in _TRUE
    elif kind is int:
        try:
            return int(text)
        except ValueError:
            pass
    elif kind is float:
        try:
            return float(text)
        except ValueError:
            pass
    else:  # str and Path
        if text.startswith("--"):  # `-o --json`: the option's value was left out
            raise ValueError(f"{value!r} looks like an option, not a value: give the value right after the option")
        return kind(value)
    raise ValueError(f"{value!r} is not a valid {_KIND[kind]}.")


def _plain_kind(annotation: Any, info: Any) -> tuple[type, bool] | None:
    """(element type, is a list) when the parameter needs nothing but a plain conversion, else None."""
    if getattr(info, "parser", None) is not None or getattr(info, "click_type", None) is not None:
        return None
    if getattr(info, "min", None) is not None or getattr(info, "max", None) is not None:
        return None
    if (
        any(getattr(info, flag, False) for flag in ("exists", "resolve_path", "allow_dash"))
        or getattr(info, "path_type", None) is not None
        or getattr(info, "file_okay", True) is not True
        or getattr(info, "dir_okay", True) is not True
        or getattr(info, "writable", False)
        or getattr(info, "readable", True) is not True
    ):
        return None
    many = get_origin(annotation) is list
    kind = get_args(annotation)[0] if many else annotation
    return (kind, many) if kind in (str, int, float, bool, Path) else None


def install() -> bool:
    """Route plain parameters around pydantic; False (and nothing changed) if typer is not as expected."""
    try:
        from typer import core
        from typer._click.exceptions import BadParameter
        from typer._coercion import RuntimeParam

        original = core._TyperParameter.get_runtime_param
    except (ImportError, AttributeError):
        return False

    @dataclass(frozen=True)
    class PlainParam(RuntimeParam):  # type: ignore[misc,valid-type]
        kind: type = str
        many: bool = False

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            try:
                if self.many:
                    return [_convert(self.kind, v) for v in (value if isinstance(value, list | tuple) else [value])]
                return _convert(self.kind, value)
            except ValueError as exc:
                raise BadParameter(str(exc), ctx=ctx, param=param) from None

    def get_runtime_param(self: Any) -> Any:
        if self._runtime_param is None:
            desc = self.type_descriptor
            plain = None if desc.file_annotation is not None else _plain_kind(desc.annotation, desc.parameter_info)
            if plain is None:
                return original(self)
            self._runtime_param = PlainParam(
                parameter_info=desc.parameter_info, annotation=desc.annotation, kind=plain[0], many=plain[1]
            )
        return self._runtime_param

    core._TyperParameter.get_runtime_param = get_runtime_param
    return True
