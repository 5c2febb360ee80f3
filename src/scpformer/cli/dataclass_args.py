"""Command-line flags generated from the frozen configuration dataclasses.

Each scalar or tuple field of a configuration dataclass becomes ``--prefix-field-name``, in
lowercase kebab-case (a ``tuple[float, float]`` takes two numbers, a ``tuple[str, ...]`` one
or more words); its help is the end-of-line comment of the field in the source (the paper
symbol and units) followed by ``(default: X)``, so that ``--help`` is the documentation and
every default of the papers' tables can be overridden. A flag whose spelling changed keeps
its old spelling for one release: hidden from ``--help``, it warns on stderr and names the
new flag (:func:`add_deprecated_alias`).

Building a parser must not import the library (cvxpy, numba and torch take seconds to load):
the flags are built from :mod:`scpformer.cli.schema`, a snapshot of the dataclasses' fields,
defaults and comments and of the named choices (solver names, stopping tests, modes, ...),
written from the live classes by ``python -m scpformer.cli.dataclass_args``. A test checks
that the snapshot is current, so a changed default or a new field fails it until the snapshot
is written again.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import importlib
import inspect
import re
import sys
import typing
from pathlib import Path
from typing import Any

#: snapshot name -> ``"module:expression"`` giving the dataclass instance whose fields become
#: flags and whose values are their defaults (a class or function is called without
#: arguments).
SOURCES: dict[str, str] = {
    "pdg6dof.solver": "scpformer.problems.pdg6dof.config:PDGSolverConfig",
    "scvx": "scpformer.scp.scvx:SCvxParameters",
    "pdg6dof.constants": "scpformer.problems.pdg6dof.constants:VehicleConstants",
    "rendezvous.solver": "scpformer.problems.rendezvous.scenario:RendezvousSolverConfig",
    "scp": "scpformer.problems.rendezvous.scenario:SCPParameters",
    "rendezvous.verification": "scpformer.problems.rendezvous.scenario:VerificationTolerances",
    "rendezvous.scenario": "scpformer.problems.rendezvous.scenario:RendezvousScenario",
    "rendezvous.target": "scpformer.problems.rendezvous.scenario:TargetOrbit",
    "rendezvous.ranges": "scpformer.problems.rendezvous.instance:SampleRanges",
    "robust.solver": "scpformer.problems.robust_rendezvous.scenario:RobustSolverConfig",
    "scvx_star": "scpformer.scp.scvx_star:SCvxStarParameters",
    "robust.verification": "scpformer.problems.robust_rendezvous.scenario:RobustVerification",
    "robust.scenario": "scpformer.problems.robust_rendezvous.scenario:RobustScenario",
    "robust.target": "scpformer.problems.robust_rendezvous.scenario:robust_target",
    "robust.ranges": "scpformer.problems.robust_rendezvous.instance:RobustSampleRanges",
    "train": "scpformer.train.config:TrainConfig",
}

#: snapshot name -> ``"module:expression"`` of a named value the parsers need (choices and
#: defaults that live in modules too slow to import for ``--help``).
CONSTANT_SOURCES: dict[str, str] = {
    "solvers": "scpformer.scp.conic:tuple(SOLVERS)",
    "scvx.stopping": "scpformer.scp.scvx:tuple(STOPPING_TESTS)",
    "scp.stopping": "scpformer.problems.rendezvous.scenario:tuple(STOP_TESTS)",
    "robust.dynamics": "scpformer.problems.robust_rendezvous.scenario:tuple(DYNAMICS)",
    "robust.modes": "scpformer.problems.robust_rendezvous.scenario:tuple(MODES)",
    "robust.waypoints": "scpformer.problems.robust_rendezvous.scenario:tuple(WAYPOINTS)",
    "robust.delta": "scpformer.problems.robust_rendezvous.instance:RobustInstance().uncertainty"
    ".delta",
    "train.schedules": "scpformer.train.config:tuple(SCHEDULES)",
    "train.devices": "scpformer.train.config:tuple(DEVICES)",
    "train.presets": "scpformer.train.config:tuple(TRAIN_PRESETS)",
    "lookup": "scpformer.models.lookup:{k: dataclasses.asdict(v) for k, v in "
    "LOOKUP_PRESETS.items()}",
    "art.modes": "scpformer.warmstart:tuple(ART_MODES)",
    "rendezvous.problems": "scpformer.problems.rendezvous.api:tuple(METHODS)",
    "rendezvous.warmstarts": "scpformer.problems.rendezvous.warmstart:tuple(RENDEZVOUS_CONVEX)",
    # --warmstart of `solve robust-rendezvous`: the method three_stage (which takes no warm
    # start), or passive_safety from the family's own warm start
    "robust.warmstarts": "scpformer.problems.robust_rendezvous.api:(METHODS[0], 'tpbvp')",
    "pdg6dof.ranges": "scpformer.data.pdg6dof_family:tuple(sorted(RANGE_PRESETS))",
    # the built-in families only (not those a program or a test registers at run time)
    "families": "scpformer.data.family:tuple((n, get_family_spec(n).summary) "
    "for n in BUILTIN_MODULES)",
    "rotation_angles": "scpformer.data.augment:tuple(ROTATION_ANGLES_DEG)",
    "experiments": "scpformer.experiments:tuple(EXPERIMENTS)",
}

#: (snapshot name, field) -> name of its choices in :data:`CONSTANT_SOURCES`
FIELD_CHOICES: dict[tuple[str, str], str] = {
    ("scvx", "solver"): "solvers",
    ("scvx", "stopping"): "scvx.stopping",
    ("scp", "solver"): "solvers",
    ("scp", "stop_test"): "scp.stopping",
    ("scvx_star", "solver"): "solvers",
    ("robust.solver", "dynamics"): "robust.dynamics",
    ("robust.ranges", "waypoints"): "robust.waypoints",
    ("train", "schedule"): "train.schedules",
    ("train", "device"): "train.devices",
}

#: (snapshot name, field) of the fields that get no flag of their own: the robust safety mode
#: is ``--mode`` of ``solve robust-rendezvous`` (``bench`` runs both modes)
NO_FLAG: frozenset[tuple[str, str]] = frozenset({("robust.solver", "safety_mode")})

_COMMENT = re.compile(r"^\s*(\w+)\s*:[^#]*#\s*(.+)$")
# Pointers into the source ("see module doc", "(module docstring)", "scpformer.scp.conic..."):
# right for a reader of the code, not for a reader of --help.
_POINTERS = (
    re.compile(r"\s*\((?:see [^)]*|(?:the )?module docstring)\)", re.IGNORECASE),
    re.compile(r"[,;]\s*see [^),;]*", re.IGNORECASE),
    re.compile(r"[,;]?\s*(?:one of |see )?scpformer(?:\.\w+)+"),
)


# ======================================================================================
# the snapshot (run time: read; development: written from the live classes)
# ======================================================================================
def snapshot_fields(name: str) -> tuple[tuple[str, str, Any, str, str | None], ...]:
    """``(field, kind, default, help, choices name)`` of every flag of snapshot ``name``."""
    from scpformer.cli import schema

    return schema.FIELDS[name]


def constant(name: str) -> Any:
    """The snapshot of the named value ``name`` of :data:`CONSTANT_SOURCES`."""
    from scpformer.cli import schema

    return schema.CONSTANTS[name]


def _resolve(source: str) -> Any:
    module_name, expression = source.split(":", 1)
    module = importlib.import_module(module_name)
    value = eval(expression, {"dataclasses": dataclasses, **vars(module)})
    return value() if callable(value) else value


def _plain(value: Any) -> Any:
    """``value`` as Python literals (numpy scalars and arrays as floats, tuples)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple) or type(value).__name__ == "ndarray":
        return tuple(_plain(v) for v in value)
    if isinstance(value, bool | int | float | str) or value is None:
        return type(value)(value) if value is not None else None
    if hasattr(value, "item"):  # numpy scalar
        return value.item()
    return value


def _kind(hint: Any, default: Any) -> str | None:
    """The flag kind of a field type, or None for a field with no flag (nested dataclass)."""
    if dataclasses.is_dataclass(hint):
        return None
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return "strs" if args[0] is str else "floats*"
        return "floats"
    return {bool: "bool", int: "int", float: "float", str: "str"}[hint]


def help_text(comment: str) -> str:
    """A field comment without pointers into the source."""
    for pattern in _POINTERS:
        comment = pattern.sub("", comment)
    return " ".join(comment.split())


def live_snapshot() -> tuple[dict[str, tuple], dict[str, Any]]:
    """``(FIELDS, CONSTANTS)`` read from the live classes and modules (imports them all)."""
    fields = {}
    for name, source in SOURCES.items():
        obj = _resolve(source)
        cls = type(obj)
        comments, hints = field_comments(cls), typing.get_type_hints(cls)
        rows = []
        for f in dataclasses.fields(cls):
            default = getattr(obj, f.name)
            kind = _kind(hints[f.name], default)
            if kind is not None and (name, f.name) not in NO_FLAG:
                help_ = help_text(comments.get(f.name, ""))
                choices = FIELD_CHOICES.get((name, f.name))
                rows.append((f.name, kind, _plain(default), help_, choices))
        fields[name] = tuple(rows)
    constants = {name: _plain(_resolve(source)) for name, source in CONSTANT_SOURCES.items()}
    return fields, constants


def write_snapshot(path: Path | None = None) -> Path:
    """Write :mod:`scpformer.cli.schema` from the live classes."""
    import pprint

    fields, constants = live_snapshot()
    path = path or Path(__file__).with_name("schema.py")
    text = (
        '"""Snapshot of the configuration dataclasses and named choices of the command line.\n\n'
        "Written by ``python -m scpformer.cli.dataclass_args`` from the live classes (see\n"
        ":mod:`scpformer.cli.dataclass_args`); do not edit by hand.\n"
        '"""\n\n'
        "# fmt: off\n"
        f"FIELDS = {pprint.pformat(fields, width=100, sort_dicts=False)}\n\n"
        f"CONSTANTS = {pprint.pformat(constants, width=100, sort_dicts=False)}\n"
    )
    path.write_text(text, encoding="utf-8")
    return path


@functools.cache  # reading the source is most of the time of writing the snapshot
def field_comments(cls: type) -> dict[str, str]:
    """Map field name -> end-of-line comment in the class source."""
    source = _class_source(cls)
    if source is None:
        return {}
    return {m.group(1): m.group(2).strip() for m in map(_COMMENT.match, source.splitlines()) if m}


def _class_source(cls: type) -> str | None:
    """The source of ``cls``: its ``class`` line and the indented block under it."""
    try:
        with open(inspect.getsourcefile(cls) or "", encoding="utf-8") as fh:
            lines = fh.read().splitlines()
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


# ======================================================================================
# flags
# ======================================================================================
def kebab(name: str) -> str:
    """``T_max`` -> ``t-max``: a field or prefix as it is spelled in a flag."""
    return name.rstrip("_").replace("_", "-").lower()


def flag(prefix: str, name: str) -> str:
    """The flag of field ``name`` under ``prefix`` (``--scvx-eta-init``)."""
    return "--" + (f"{prefix}-" if prefix else "") + kebab(name)


def dest(prefix: str, name: str) -> str:
    """The argparse destination of field ``name`` under ``prefix``."""
    return f"{prefix.replace('-', '_')}__{name}" if prefix else f"__{name}"


def format_default(value: Any) -> str:
    """A default as it is typed on the command line (tuples space-separated)."""
    if isinstance(value, list | tuple):
        return " ".join(format_default(v) for v in value)
    return repr(value) if isinstance(value, float) else str(value)


def with_default(text: str, default: Any) -> str:
    """``text (default: X)``: the one style of defaults in every help."""
    return f"{text} (default: {format_default(default)})".lstrip()


def warn_deprecated(old: str, new: str) -> None:
    """The one-line warning of an old flag spelling."""
    print(f"scpformer: warning: {old} is deprecated and will be removed; use {new}",
          file=sys.stderr)  # fmt: skip


@functools.cache
def _deprecated_class(base: type[argparse.Action]) -> type[argparse.Action]:
    """``base`` that first warns that its (old) option string is deprecated."""

    class Deprecated(base):  # type: ignore[misc, valid-type]
        def __init__(self, *args: Any, new_flag: str, **kwargs: Any) -> None:
            super().__init__(*args, **kwargs)
            self.new_flag = new_flag

        def __call__(self, parser, namespace, values, option_string=None) -> None:
            new = self.new_flag
            if option_string and option_string.startswith("--no-"):
                new = "--no-" + new[2:]
            warn_deprecated(option_string or self.option_strings[0], new)
            super().__call__(parser, namespace, values, option_string)

    Deprecated.__name__ = f"Deprecated{base.__name__}"
    return Deprecated


def add_deprecated_alias(
    container: argparse._ActionsContainer, old: str, action: argparse.Action
) -> argparse.Action:
    """Accept ``old`` as a hidden spelling of ``action``'s flag that warns when used."""
    kwargs: dict[str, Any] = {"dest": action.dest, "help": argparse.SUPPRESS}
    kwargs["new_flag"] = action.option_strings[0]
    if isinstance(action, argparse.BooleanOptionalAction):
        kwargs["default"] = action.default
    elif action.nargs == 0:  # store_true / store_const
        kwargs["default"] = action.default
        if isinstance(action, argparse._StoreConstAction):
            kwargs["const"] = action.const
    else:
        kwargs.update(nargs=action.nargs, type=action.type, choices=action.choices,
                      metavar=action.metavar, default=action.default)  # fmt: skip
    if kwargs.get("default") is None:
        kwargs.pop("default", None)
    return container.add_argument(old, action=_deprecated_class(type(action)), **kwargs)


def add_dataclass_arguments(
    parser: argparse.ArgumentParser,
    name: str,
    prefix: str = "",
    title: str | None = None,
    *,
    legacy_prefix: str | None = None,
    renames: dict[str, str] | None = None,
    hidden: bool = False,
    print_defaults: bool = True,
    defaults_unless: str | None = None,
    default_note: str | None = None,
) -> argparse._ArgumentGroup:
    """Add one flag per field of the snapshot ``name`` (see :data:`SOURCES`) to a group.

    ``renames`` maps a field to its flag name where the two differ (one spelling per concept
    across families); ``legacy_prefix`` is the flags' former prefix. Old spellings (mixed
    case, former prefix or name) stay as deprecated aliases. ``hidden`` keeps the flags out
    of ``--help`` (the constants of the papers' tables, listed by ``--print-config``);
    ``print_defaults`` False when the effective default depends on other flags (a preset):
    ``--print-config`` then writes given values only, and so it does when the flag (dest)
    ``defaults_unless`` is given (``instance``: the defaults are then the instance file's).
    ``default_note`` replaces the ``(default: X)`` of every help.
    """
    group = parser.add_argument_group(title or name)
    renames = renames or {}
    for field, kind, default, comment, choices_name in snapshot_fields(name):
        key = renames.get(field, field)
        new = flag(prefix, key)
        choices = constant(choices_name) if choices_name else None
        help_ = (
            argparse.SUPPRESS
            if hidden
            else (f"{comment} ({default_note})" if default_note else with_default(comment, default))
        )
        kwargs: dict[str, Any] = {"dest": dest(prefix, field), "help": help_}
        if kind == "bool":
            action = group.add_argument(
                new, action=argparse.BooleanOptionalAction, default=None, **kwargs
            )
        elif kind in ("floats", "floats*", "strs"):
            action = group.add_argument(
                new,
                type=str if kind == "strs" else float,
                nargs=len(default) if kind == "floats" else "+",
                metavar=kebab(field).upper().replace("-", "_"),
                choices=choices,
                **kwargs,
            )
        else:
            action = group.add_argument(
                new,
                type={"int": int, "float": float, "str": str}[kind],
                choices=choices,
                metavar=None if choices else kebab(field).upper().replace("-", "_"),
                **kwargs,
            )
        action.config_section = prefix or None
        action.config_key = kebab(key)
        action.config_default = default if print_defaults else None
        action.config_default_unless = defaults_unless
        olds = {flag(prefix, field).lower()}
        olds.add("--" + (f"{prefix}-" if prefix else "") + field.rstrip("_").replace("_", "-"))
        if legacy_prefix is not None:
            olds.add("--" + f"{legacy_prefix}-" + field.rstrip("_").replace("_", "-"))
            olds.add(flag(legacy_prefix, field))
        for old in sorted(olds - {new}):
            add_deprecated_alias(group, old, action)
    return group


def overrides(args: argparse.Namespace, cls: type, prefix: str = "") -> dict[str, Any]:
    """The fields of ``cls`` given on the command line or in ``--config`` (None: not given)."""
    out = {}
    for f in dataclasses.fields(cls):
        value = getattr(args, dest(prefix, f.name), None)
        if value is not None:
            out[f.name] = tuple(value) if isinstance(value, list) else value
    return out


def nested_overrides(args: argparse.Namespace, cls: type, sections: dict[str, str]) -> Any:
    """``cls`` with the command-line overrides of its own fields and, for each nested dataclass
    field ``name`` of ``sections``, of that field's class under the prefix ``sections[name]``."""
    hints = typing.get_type_hints(cls)
    nested = {name: hints[name](**overrides(args, hints[name], prefix))
              for name, prefix in sections.items()}  # fmt: skip
    return cls(**nested, **overrides(args, cls))


def with_overrides(base: Any, args: argparse.Namespace, cls: type, prefix: str = "") -> Any:
    """``base`` (an instance of the dataclass ``cls``) with the command-line overrides applied."""
    changes = overrides(args, cls, prefix)
    return dataclasses.replace(base, **changes) if changes else base


if __name__ == "__main__":
    print(f"wrote {write_snapshot()}")
