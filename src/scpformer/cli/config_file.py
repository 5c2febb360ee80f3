"""``--config FILE.toml`` and ``--print-config``: a command's configuration in a file.

Every command that takes configuration flags also takes

* ``--config FILE.toml``: the values of the file, under the flags given on the command line
  (a flag overrides the file);
* ``--print-config``: the resolved configuration (every flag's value, given or default) as
  TOML, which ``--config`` reads back to the same values, and exit.

The file's keys are the flags' names: a flag ``--name`` is the top-level key ``name``, and a
flag of a configuration section (``--scvx-eta-init``, section ``scvx``) is the key
``eta-init`` of the table ``[scvx]``. Values are checked by the flags' own types and choices,
so an error names the file, the key and what is wrong.

The TOML is written by :func:`dumps` (floats as ``repr``, so they read back exactly) and read
by :mod:`tomllib` (``tomli`` before Python 3.11).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from scpformer.cli.errors import OneLineParser

CONFIG, PRINT_CONFIG = "--config", "--print-config"


def add_config_file_arguments(parser: argparse.ArgumentParser) -> None:
    """``--config FILE.toml`` and ``--print-config`` (see the module docstring)."""
    group = parser.add_argument_group("configuration file")
    group.add_argument(
        CONFIG,
        type=Path,
        metavar="FILE",
        help="read flag values from this TOML file (keys as --print-config writes them); "
        "flags on the command line override it",
    )
    group.add_argument(
        PRINT_CONFIG,
        action="store_true",
        help="print the resolved configuration as TOML (for --config) and exit",
    )


# ======================================================================================
# writing
# ======================================================================================
def _string(text: str) -> str:
    escapes = {'"': '\\"', "\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r"}
    out = []
    for char in text:
        if char in escapes:
            out.append(escapes[char])
        elif ord(char) < 0x20 or ord(char) == 0x7F:
            out.append(f"\\u{ord(char):04x}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def toml_value(value: Any) -> str:
    """One TOML value: floats as ``repr`` (exact), paths as strings, sequences as arrays."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str | Path):
        return _string(str(value))
    if isinstance(value, list | tuple):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    raise TypeError(f"no TOML value for {type(value).__name__} {value!r}")


def _key(name: str) -> str:
    bare = name and all(c.isalnum() or c in "-_" for c in name) and name.isascii()
    return name if bare else _string(name)


def dumps(config: dict[str, Any]) -> str:
    """TOML text of ``config``: top-level values first, then one table per dict value."""
    lines = [f"{_key(k)} = {toml_value(v)}" for k, v in config.items() if not isinstance(v, dict)]
    for section, table in config.items():
        if isinstance(table, dict):
            lines += ["", f"[{_key(section)}]"]
            lines += [f"{_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines).lstrip("\n") + "\n"


# ======================================================================================
# the flags of a parser as configuration entries
# ======================================================================================
def _entries(parser: argparse.ArgumentParser) -> dict[tuple[str | None, str], argparse.Action]:
    """``(section, key) -> action`` of every configuration flag of ``parser``."""
    out = {}
    for action in parser._actions:
        if not action.option_strings or action.help == argparse.SUPPRESS:
            continue  # positionals, deprecated aliases
        if isinstance(action, argparse._HelpAction | argparse._VersionAction):
            continue
        if action.option_strings[0] in (CONFIG, PRINT_CONFIG):
            continue
        section = getattr(action, "config_section", None)
        key = getattr(action, "config_key", None) or action.option_strings[0][2:]
        out[section, key] = action
    for action in parser._actions:  # hidden dataclass flags (Table 1's constants)
        if action.help == argparse.SUPPRESS and hasattr(action, "config_key"):
            out[action.config_section, action.config_key] = action
    return out


def resolved(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, Any]:
    """The configuration of ``args``: every flag's value (a dataclass field not given: its
    default), sections as nested dicts; flags without a value (None) are left out."""
    config: dict[str, Any] = {}
    for (section, key), action in _entries(parser).items():
        value = getattr(args, action.dest, None)
        unless = getattr(action, "config_default_unless", None)
        if value is None and (unless is None or getattr(args, unless, None) is None):
            value = getattr(action, "config_default", None)
        if value is None:
            continue
        if isinstance(value, Path):
            value = str(value)
        if isinstance(value, list | tuple):
            value = [str(v) if isinstance(v, Path) else v for v in value]
        (config.setdefault(section, {}) if section else config)[key] = value
    return config


def print_config(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    """Handler of ``--print-config``."""
    sys.stdout.write(dumps(resolved(parser, args)))
    return 0


# ======================================================================================
# reading
# ======================================================================================
def load_toml(path: Path) -> dict[str, Any]:
    """The TOML file at ``path`` as a dict."""
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def _convert(action: argparse.Action, value: Any) -> Any:
    """``value`` of the file checked and converted as the flag's own argument would be."""
    if isinstance(value, bool) or isinstance(value, dict):
        raise ValueError(f"expected {_expected(action)}, got {value!r}")
    text = repr(value) if isinstance(value, float) else str(value)
    try:
        result = action.type(text) if callable(action.type) else text
    except (TypeError, ValueError, argparse.ArgumentTypeError) as err:
        raise ValueError(f"{err}") from None
    if action.choices is not None and result not in action.choices:
        choices = ", ".join(map(str, action.choices))
        raise ValueError(f"invalid choice {value!r} (choose from {choices})")
    return result


def _expected(action: argparse.Action) -> str:
    name = getattr(action.type, "__name__", "text") if action.type else "text"
    return {"float": "a number", "int": "an integer", "Path": "a path"}.get(name, name)


def config_value(action: argparse.Action, value: Any) -> Any:
    """The namespace value of ``action`` for the file value ``value``."""
    if isinstance(action, argparse.BooleanOptionalAction) or action.nargs == 0:
        if not isinstance(value, bool):
            raise ValueError(f"expected true or false, got {value!r}")
        if isinstance(action, argparse._StoreConstAction) and not isinstance(
            action, argparse._StoreTrueAction | argparse._StoreFalseAction
        ):
            return action.const if value else action.default
        return value
    many = isinstance(action, argparse._AppendAction) or action.nargs not in (None, "?")
    if not many:
        return _convert(action, value)
    if not isinstance(value, list):
        raise ValueError(f"expected a list, got {value!r}")
    if isinstance(action.nargs, int) and len(value) != action.nargs:
        raise ValueError(f"expected {action.nargs} values, got {len(value)}")
    if action.nargs == "+" and not value:
        raise ValueError("expected at least one value")
    return [_convert(action, v) for v in value]


def read_config(parser: argparse.ArgumentParser, path: Path) -> dict[str, Any]:
    """``dest -> value`` of every entry of the file ``path`` (one ``error:`` line if not)."""
    try:
        data = load_toml(path)
    except (OSError, ValueError) as err:  # tomllib.TOMLDecodeError is a ValueError
        reason = getattr(err, "strerror", None) or str(err)
        parser.error(f"{CONFIG} {path}: {reason}")
    entries = _entries(parser)
    values: dict[str, Any] = {}
    for name, item in data.items():
        items = item.items() if isinstance(item, dict) else [(name, item)]
        section = name if isinstance(item, dict) else None
        for key, value in items:
            where = f"{section}.{key}" if section else key
            action = entries.get((section, key))
            if action is None:
                known = "--" + (f"{section}-" if section else "") + key
                parser.error(f"{CONFIG} {path}: unknown key {where!r} (no flag {known})")
            try:
                values[action.dest] = config_value(action, value)
            except ValueError as err:
                parser.error(f"{CONFIG} {path}: {where}: {err}")
            action.required = False  # given by the file
    return values


def _config_argument(args: Sequence[str]) -> str | None:
    """The (last) value of ``--config`` in ``args``, as written."""
    path = None
    for i, arg in enumerate(args):
        if arg == "--":
            break
        if arg == CONFIG and i + 1 < len(args):
            path = args[i + 1]
        elif arg.startswith(CONFIG + "="):
            path = arg.split("=", 1)[1]
    return path


class ConfigParser(OneLineParser):
    """A parser whose commands with ``--config`` start from the file's values and whose
    ``--print-config`` replaces the command's handler (so that its errors stay one line)."""

    def parse_known_args(self, args=None, namespace=None):
        if CONFIG not in self._option_string_actions:
            return super().parse_known_args(args, namespace)
        args = list(sys.argv[1:] if args is None else args)
        path = _config_argument(args)
        if path is not None:
            namespace = namespace or argparse.Namespace()
            for key, value in read_config(self, Path(path)).items():
                setattr(namespace, key, value)  # defaults: a flag given overrides them
        result, extras = super().parse_known_args(args, namespace)
        if path is None and getattr(result, "config", None) is not None:
            self.error(f"{CONFIG}: write the flag in full (it was abbreviated)")
        if getattr(result, "print_config", False):
            parser = self
            result.handler = lambda parsed: print_config(parser, parsed)
        return result, extras
