"""What a problem family implements to be generated, stored and served as a dataset.

A family plugs into the engine through :class:`DatasetFamily`: it draws one instance theta from
a numpy Generator, solves it, and returns a :class:`SampleResult` whose fields follow the
family's :func:`~DatasetFamily.schema`. The engine owns everything else: seeds, workers, time
limits, shards, manifests, splits. Families are found by name through a registry that imports
their module lazily, so a family lands by adding one module that defines ``SPEC``:

=====================  ===============================================  ===========
name                   module                                           status
=====================  ===============================================  ===========
``pdg6dof``            :mod:`scpformer.data.pdg6dof_family`             implemented
``rendezvous``         :mod:`scpformer.data.rendezvous_family`          implemented
``robust-rendezvous``  :mod:`scpformer.data.robust_rendezvous_family`   implemented
=====================  ===============================================  ===========

Every sample also carries the engine's :data:`COMMON_FIELDS` (index, base index, status,
message, wall time).
"""

from __future__ import annotations

import dataclasses
import importlib
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from importlib import metadata
from typing import Any, ClassVar, Protocol, TypeVar, runtime_checkable

import numpy as np

from scpformer.data.errors import DatasetError
from scpformer.scp.solution import Status

_Family = TypeVar("_Family")

DTYPES = ("float64", "float32", "int64", "int32", "bool", "str")


@dataclass(frozen=True, kw_only=True)
class Field:
    """One per-sample quantity: name, dtype, per-sample shape, and meaning."""

    name: str  # HDF5 dataset name
    dtype: str  # one of DTYPES
    shape: tuple[int, ...] = ()  # shape of one sample's value
    deterministic: bool = True  # False for timings: left out of the content digest
    normalize: bool = False  # standardized by the split's training statistics
    doc: str = ""  # meaning, units, paper symbol

    def __post_init__(self) -> None:
        if self.dtype not in DTYPES:
            raise ValueError(f"field {self.name}: dtype must be one of {DTYPES}, got {self.dtype}")
        object.__setattr__(self, "shape", tuple(int(s) for s in self.shape))

    @property
    def numpy_dtype(self) -> np.dtype:
        """The in-memory numpy dtype (``object`` for strings)."""
        return np.dtype(object) if self.dtype == "str" else np.dtype(self.dtype)

    def fill_value(self) -> Any:
        """Value of a sample that has none (NaN, -1, False or the empty string)."""
        return {"str": "", "bool": False}.get(
            self.dtype, np.nan if self.dtype.startswith("float") else -1
        )

    def empty(self, count: int) -> np.ndarray:
        """A column of ``count`` fill values, shape (count, *shape)."""
        return np.full((count, *self.shape), self.fill_value(), dtype=self.numpy_dtype)

    def coerce(self, value: Any) -> np.ndarray:
        """One sample's value as an array of this field's dtype and shape."""
        if self.dtype == "str":
            return np.array(str(value), dtype=object)
        array = np.asarray(value, dtype=self.numpy_dtype)
        if array.shape != self.shape:
            raise ValueError(f"field {self.name}: expected shape {self.shape}, got {array.shape}")
        return array

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (written into the manifest)."""
        return dataclasses.asdict(self) | {"shape": list(self.shape)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Field:
        """Inverse of :meth:`to_dict`."""
        return cls(**{**data, "shape": tuple(data.get("shape", ()))})


COMMON_FIELDS: tuple[Field, ...] = (
    Field(name="index", dtype="int64", doc="sample index in this dataset"),
    Field(name="base_index", dtype="int64", doc="index of the solved base instance (split group)"),
    Field(name="status", dtype="str", doc="outcome of the solve (family status or engine status)"),
    Field(name="message", dtype="str", doc="why, when the status is not success"),
    Field(name="wall_time", dtype="float64", deterministic=False, doc="s to sample and solve"),
)

# Statuses the engine itself assigns when a solve does not return.
TIMEOUT = "timeout"  # exceeded the per-instance time limit; the worker was restarted
WORKER_CRASHED = "worker_crashed"  # the worker process died on this instance
ERROR = "error"  # the family raised an exception (message holds it)


@dataclass(frozen=True)
class SampleResult:
    """What a family returns for one instance: status, message and its schema's fields."""

    status: str
    message: str
    fields: dict[str, Any]
    solve_time: float = 0.0  # s inside the family's solver (for the overhead measurement)


@runtime_checkable
class DatasetFamily(Protocol):
    """A problem family as the dataset engine sees it (see the module docstring).

    Objects must be picklable (they travel to worker processes and Ray actors) and
    deterministic: the same instance gives the same deterministic fields in any process.
    """

    name: str  # registry name, e.g. "pdg6dof"
    success_statuses: frozenset[str]  # statuses counted as solved (others count as failed)

    def config_dict(self) -> dict[str, Any]:
        """The full resolved configuration, JSON-ready (written to the manifest)."""

    def schema(self) -> tuple[Field, ...]:
        """The family's per-sample fields (the engine adds :data:`COMMON_FIELDS`)."""

    def versions(self) -> dict[str, str]:
        """Versions of the libraries the results depend on (solver, numpy, ...)."""

    def warm_up(self) -> None:
        """Per-process setup before the first timed solve (e.g. compile the subproblem)."""

    def sample(self, rng: np.random.Generator) -> Any:
        """Draw one instance theta from ``rng`` (the instance's own stream)."""

    def encode_instance(self, instance: Any) -> dict[str, Any]:
        """The fields that describe ``instance`` alone (theta); used for failed samples too."""

    def solve(self, instance: Any) -> SampleResult:
        """Solve ``instance``; solver failures are statuses, not exceptions."""


def full_schema(family: DatasetFamily) -> tuple[Field, ...]:
    """:data:`COMMON_FIELDS` followed by the family's fields; names must be unique."""
    fields = (*COMMON_FIELDS, *family.schema())
    names = [f.name for f in fields]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"family {family.name}: duplicated field name(s) {duplicated}")
    return fields


@dataclass(frozen=True, kw_only=True)
class FamilySpec:
    """A registered family: its name, a summary, and how to build it from a config dict."""

    name: str  # registry and command-line name
    summary: str  # one line for --help
    build: Callable[[Mapping[str, Any] | None], DatasetFamily]  # None: paper defaults


def family_from_config(
    family: Callable[..., _Family], config_class: Any, config: Mapping[str, Any] | None
) -> _Family:
    """A family's :attr:`FamilySpec.build`: ``family(config_class.from_dict(config))``, or
    ``family()`` (its paper defaults) when ``config`` is ``None`` or empty."""
    if not config:
        return family()
    return family(config_class.from_dict(config))


class ConfiguredFamily:
    """What the built-in families share: a frozen dataclass whose one field ``config`` is an
    instance of ``config_class`` (plain values, read back by ``config_class.from_dict``), and
    a sample counts as solved when it converged."""

    config: Any
    config_class: ClassVar[Any]
    name: ClassVar[str]
    success_statuses: ClassVar[frozenset[str]] = frozenset({Status.CONVERGED.value})

    def config_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self.config)

    @classmethod
    def from_config(cls, config: Mapping[str, Any] | None = None) -> Any:
        """The family from a resolved config dict (a manifest's), or with its paper defaults
        when ``config`` is ``None`` or empty: the :attr:`FamilySpec.build` of the family."""
        return family_from_config(cls, cls.config_class, config)

    @classmethod
    def spec(cls, summary: str) -> FamilySpec:
        """The registry entry of the family: its ``name``, ``summary``, :meth:`from_config`."""
        return FamilySpec(name=cls.name, summary=summary, build=cls.from_config)


# Built-in families and the module that defines each one's ``SPEC``.
BUILTIN_MODULES: dict[str, str] = {
    "pdg6dof": "scpformer.data.pdg6dof_family",
    "rendezvous": "scpformer.data.rendezvous_family",
    "robust-rendezvous": "scpformer.data.robust_rendezvous_family",
}
_REGISTRY: dict[str, FamilySpec] = {}


def register_family(spec: FamilySpec, *, replace: bool = False) -> FamilySpec:
    """Add ``spec`` to the registry (``replace`` to overwrite an existing name)."""
    if spec.name in _REGISTRY and not replace:
        raise ValueError(f"dataset family {spec.name!r} is already registered")
    _REGISTRY[spec.name] = spec
    return spec


def family_names() -> list[str]:
    """Names of every known family: built-in (landed or not) and registered."""
    return list(dict.fromkeys([*BUILTIN_MODULES, *_REGISTRY]))


def check_family_name(name: Any, where: str = "") -> str:
    """``name`` if it names a known family (:func:`family_names`), without importing it.

    Raises
    ------
    DatasetError
        ``{where}unknown dataset family NAME (known: ...)`` for any other value.
    """
    known = family_names()
    if not isinstance(name, str) or name not in known:
        raise DatasetError(f"{where}unknown dataset family {name!r} (known: {', '.join(known)})")
    return name


def get_family_spec(name: str) -> FamilySpec:
    """The spec of family ``name``, importing its module on first use.

    Raises
    ------
    DatasetError
        For an unknown name, or a built-in family whose module has not landed yet.
    """
    if name in _REGISTRY:
        return _REGISTRY[name]
    module_name = BUILTIN_MODULES[check_family_name(name)]
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as err:
        if err.name != module_name:
            raise
        raise DatasetError(
            f"dataset family {name!r} is not available yet: {module_name} has not landed"
        ) from None
    spec = getattr(module, "SPEC", None)
    if not isinstance(spec, FamilySpec):
        raise DatasetError(f"{module_name} defines no FamilySpec named SPEC")
    return _REGISTRY.setdefault(name, spec)


def build_family(name: str, config: Mapping[str, Any] | None = None) -> DatasetFamily:
    """The family ``name`` built from a resolved config dict (a manifest's), or defaults."""
    return get_family_spec(name).build(config)


def package_versions(packages: Iterable[str]) -> dict[str, str]:
    """Installed version of each named package (``"unknown"`` when not installed)."""
    out = {}
    for name in packages:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "unknown"
    return out


def dataclass_from_dict(cls: type, data: Mapping[str, Any]) -> Any:
    """Rebuild a (nested) frozen dataclass from :func:`dataclasses.asdict` output.

    Lists become tuples, nested dataclass fields recurse, and unknown keys raise
    ``ValueError`` naming them, so a hand-edited manifest fails clearly.
    """
    if not isinstance(data, Mapping):
        raise ValueError(
            f"the dataset's configuration holds a JSON {type(data).__name__} where an object "
            "belongs (an edited manifest?)"
        )
    hints = typing.get_type_hints(cls)
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(
            f"the dataset's configuration has field(s) {', '.join(unknown)} that this family "
            "does not know (data of another family, or an edited manifest?)"
        )
    kwargs = {}
    for name, value in data.items():
        kind = _dataclass_in(hints[name])
        kwargs[name] = dataclass_from_dict(kind, value) if kind else _tuples(value)
    return cls(**kwargs)


def _dataclass_in(hint: Any) -> type | None:
    if dataclasses.is_dataclass(hint):
        return hint
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        return next((a for a in typing.get_args(hint) if dataclasses.is_dataclass(a)), None)
    return None


def _tuples(value: Any) -> Any:
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value
