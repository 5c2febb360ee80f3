"""Command-line flags generated from frozen configuration dataclasses.

Each scalar or tuple field becomes ``--prefix-field-name`` (a ``tuple[float, float]`` takes
two numbers, a ``tuple[str, ...]`` one or more words); its help text is the
end-of-line comment of the field in the source (the paper symbol and units), so that ``--help``
is the documentation and every default of the papers' tables can be overridden.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import inspect
import re
import typing
from typing import Any

_COMMENT = re.compile(r"^\s*(\w+)\s*:[^#]*#\s*(.+)$")


@functools.cache  # reading the source is most of the time of building the parser
def field_comments(cls: type) -> dict[str, str]:
    """Map field name -> end-of-line comment in the class source."""
    source = _class_source(cls)
    if source is None:
        return {}
    return {m.group(1): m.group(2).strip() for m in map(_COMMENT.match, source.splitlines()) if m}


@functools.cache
def _source_lines(path: str) -> tuple[str, ...]:
    with open(path, encoding="utf-8") as fh:
        return tuple(fh.read().splitlines())


def _class_source(cls: type) -> str | None:
    """The source of ``cls``: its ``class`` line and the indented block under it.

    ``inspect.getsource`` parses the whole module for each class (milliseconds per class,
    tens of them per parser); a module with one ``class Name`` line is read directly and
    only an ambiguous one is left to ``inspect``.
    """
    try:
        lines = _source_lines(inspect.getsourcefile(cls) or "")
    except (OSError, TypeError):
        return None
    header = re.compile(rf"^(\s*)class {re.escape(cls.__name__)}\b")
    starts = [i for i, line in enumerate(lines) if header.match(line)]
    if len(starts) != 1:
        try:
            return inspect.getsource(cls)
        except (OSError, TypeError):
            return None
    indent = len(header.match(lines[starts[0]]).group(1))
    end = starts[0] + 1
    while end < len(lines) and (
        not lines[end].strip() or len(lines[end]) - len(lines[end].lstrip()) > indent
    ):
        end += 1
    return "\n".join(lines[starts[0] : end])


def _flag(prefix: str, name: str) -> str:
    return "--" + (f"{prefix}-" if prefix else "") + name.rstrip("_").replace("_", "-")


def add_dataclass_arguments(
    parser: argparse.ArgumentParser, cls: type, prefix: str = "", title: str | None = None
) -> None:
    """Add one flag per field of ``cls`` (nested dataclasses get their own flag prefix)."""
    group = parser.add_argument_group(title or cls.__name__)
    comments = field_comments(cls)
    hints = typing.get_type_hints(cls)
    defaults = cls()
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        default = getattr(defaults, f.name)
        dest = f"{prefix}__{f.name}" if prefix else f"__{f.name}"
        if dataclasses.is_dataclass(hint):
            continue
        help_text = f"{comments.get(f.name, '')} (default: {default})"
        origin = typing.get_origin(hint)
        if origin is tuple:
            args = typing.get_args(hint)
            variable = len(args) == 2 and args[1] is Ellipsis  # tuple[str, ...]: one or more
            group.add_argument(
                _flag(prefix, f.name),
                dest=dest,
                type=args[0] if variable else float,
                nargs="+" if variable else len(default),
                metavar=f.name.upper(),
                help=help_text,
            )
        elif hint is bool:
            group.add_argument(
                _flag(prefix, f.name),
                dest=dest,
                action=argparse.BooleanOptionalAction,
                default=None,
                help=help_text,
            )
        else:
            group.add_argument(
                _flag(prefix, f.name), dest=dest, type=hint, metavar=f.name.upper(), help=help_text
            )


def overrides(args: argparse.Namespace, cls: type, prefix: str = "") -> dict[str, Any]:
    """The fields of ``cls`` given on the command line (``None`` means not given)."""
    out = {}
    for f in dataclasses.fields(cls):
        dest = f"{prefix}__{f.name}" if prefix else f"__{f.name}"
        value = getattr(args, dest, None)
        if value is not None:
            out[f.name] = tuple(value) if isinstance(value, list) else value
    return out


def with_overrides(base: Any, args: argparse.Namespace, cls: type, prefix: str = "") -> Any:
    """``base`` (an instance of the dataclass ``cls``) with the command-line overrides applied."""
    changes = overrides(args, cls, prefix)
    return dataclasses.replace(base, **changes) if changes else base
