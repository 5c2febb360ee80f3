"""The warm-start interface shared by every problem family, and the registry of names.

A warm start provider turns an instance into an initial guess for the SCP and says what it
did: ``provider.guess(instance) -> WarmStartResult`` with the guess (a
:class:`~scpformer.scp.solution.Trajectory`, or None when the provider failed) and a
:class:`WarmStartRecord` (which provider produced the guess, how long it took, the guess's
cost and constraint-to-go, and, for learned providers, the acceptance decision and the
fallback used). A guess is never a solution: the SCP always runs after it.

The interface lives at the ``scp`` layer so that the problem families, which implement the
non-learned providers (analytic guesses, their own convex Problems 1-2), can use it without
importing upward. The learned providers (:mod:`scpformer.warmstart`) register their names
with :func:`register`; a family's ``solve`` maps a name onto a provider with
:func:`resolve`, its own names first.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Protocol, runtime_checkable

import numpy as np

from scpformer.scp.solution import Solution, Trajectory
from scpformer.validation import check_type


@dataclass(frozen=True, kw_only=True)
class WarmStartRecord:
    """What a warm start provider did for one instance (stored in ``Solution.extras``).

    ``source`` is the provider that was asked; when its own guess was rejected (``accepted``
    False), ``fallback_source`` names the provider whose guess was used instead and
    ``cost`` / ``constraint_to_go`` describe that guess (the one the SCP starts from).
    """

    source: str  # provider asked: "convex", "tpbvp", "art", "straight_line", "trajectory", ...
    time_s: float  # wall time of the whole guess, fallback included [s]
    cost: float  # cost of the returned guess (sum |dv|_2 [m/s] for rendezvous; nan if unknown)
    constraint_to_go: float  # C(t_1) of the returned guess (Eqs. 5, 21 / robust Eq. 7; nan: n/a)
    accepted: bool = True  # the source's own guess is the one returned
    reason: str = ""  # why (acceptance check, failure message)
    fallback_source: str | None = None  # provider of the returned guess when not accepted
    details: dict[str, Any] = field(default_factory=dict)  # provider-specific facts

    @property
    def used(self) -> str:
        """The provider whose guess the SCP starts from."""
        return (
            self.source if self.accepted or self.fallback_source is None else self.fallback_source
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values (for ``Solution.extras["warmstart"]``, JSON and summaries)."""
        out = asdict(self)
        out["used"] = self.used
        return out


@dataclass(frozen=True)
class WarmStartResult:
    """A provider's guess and its record; ``solution`` is the solve behind it, if any."""

    trajectory: Trajectory | None
    record: WarmStartRecord
    solution: Solution | None = None  # e.g. the convex solve that produced (or backs) the guess


@runtime_checkable
class WarmStart(Protocol):
    """Anything that produces an initial guess for an instance."""

    def guess(self, instance: Any) -> WarmStartResult:
        """The initial guess for ``instance`` and a record of how it was made."""
        ...


def check_instance(instance: Any, cls: type, family: str) -> None:
    """``ValueError`` naming the family when ``instance`` is not a ``cls``."""
    if not isinstance(instance, cls):
        raise ValueError(
            f"instance must be a {cls.__name__} ({family}), got {type(instance).__name__}"
        )


def is_provider(value: Any) -> bool:
    """True for a warm start provider (an object with a callable ``guess``)."""
    return callable(getattr(value, "guess", None)) and not isinstance(value, type)


def trajectory_cost(trajectory: Trajectory) -> float:
    """``sum_k |u_k|_2`` of a trajectory's controls (the rendezvous cost, Eq. 4 with a minus)."""
    u = np.asarray(trajectory.u, dtype=float)
    return float(np.linalg.norm(u, axis=-1).sum()) if u.ndim == 2 and u.size else math.nan


@dataclass(frozen=True)
class GivenWarmStart:
    """A fixed guess: a :class:`Trajectory`, the trajectory of a :class:`Solution`, or states.

    ``cost`` defaults to the solution's cost, else ``sum |u|`` of the trajectory.
    """

    value: Trajectory | Solution | np.ndarray
    source: str = ""

    def guess(self, instance: Any) -> WarmStartResult:
        value, solution = self.value, None
        if isinstance(value, Solution):
            solution, value = value, value.trajectory
        if value is None:
            record = WarmStartRecord(
                source=self.source or "solution", time_s=0.0, cost=math.nan,
                constraint_to_go=math.nan, accepted=False,
                reason=f"the given solution has no trajectory ({solution.message})",
            )  # fmt: skip
            return WarmStartResult(None, record, solution)
        if not isinstance(value, Trajectory):
            value = Trajectory(x=np.asarray(value, dtype=float), u=np.zeros((0, 0)), p=np.zeros(0))
        cost = solution.cost if solution is not None else trajectory_cost(value)
        source = self.source or ("solution" if solution is not None else "trajectory")
        record = WarmStartRecord(source=source, time_s=0.0, cost=cost, constraint_to_go=math.nan)
        return WarmStartResult(value, record, solution)


@dataclass(frozen=True)
class PrecomputedWarmStart:
    """A :class:`WarmStartResult` computed beforehand (e.g. by a batched ``guess_batch``)."""

    result: WarmStartResult

    def guess(self, instance: Any) -> WarmStartResult:
        return self.result


def timed(record: WarmStartRecord, start: float) -> WarmStartRecord:
    """``record`` with ``time_s`` = the wall time since ``start`` (``time.perf_counter``)."""
    return replace(record, time_s=time.perf_counter() - start)


def guess_each(provider: WarmStart, instances: Sequence[Any]) -> list[WarmStartResult]:
    """``provider.guess`` of every instance, in order (the batch of a provider without one)."""
    return [provider.guess(instance) for instance in instances]


def as_provider(warmstart: Any, named: dict[str, Any]) -> WarmStart:
    """Map what a solve function accepts onto a provider.

    Parameters
    ----------
    warmstart
        A provider (kept), a :class:`WarmStartResult` (used as is), a name among ``named``,
        a :class:`Solution`, a :class:`Trajectory` or an array of states.
    named
        The family's named providers, name -> zero-argument factory.
    """
    if isinstance(warmstart, WarmStartResult):
        return PrecomputedWarmStart(warmstart)
    if isinstance(warmstart, str):
        if warmstart not in named:
            raise ValueError(f"warmstart must be one of {tuple(named)}, got {warmstart!r}")
        return named[warmstart]()
    if is_provider(warmstart):
        return warmstart
    if isinstance(warmstart, Solution | Trajectory | np.ndarray | list | tuple):
        return GivenWarmStart(warmstart)
    raise ValueError(
        "warmstart must be a name, a WarmStart provider, a Solution, a Trajectory or an "
        f"array of states, got {type(warmstart).__name__}"
    )


# family -> name -> factory of a learned provider: factory(config) -> the provider with the
# family's default model, for a solve under the solver configuration ``config``
_REGISTRY: dict[str, dict[str, Callable[[Any], WarmStart]]] = {}


def register(family: str, name: str, factory: Callable[[Any], WarmStart]) -> None:
    """Register the learned warm start ``name`` of ``family`` (e.g. ``"pdg6dof"``,
    ``"tscvx"``); ``factory(config)`` builds the provider with the family's default model for
    a solve under the family's solver configuration ``config``."""
    _REGISTRY.setdefault(family, {})[name] = factory


def registered(family: str) -> dict[str, Callable[[Any], WarmStart]]:
    """The learned warm starts registered for ``family``, name -> factory."""
    return dict(_REGISTRY.get(family, {}))


def resolve(
    warmstart: Any,
    family: str,
    named: dict[str, Callable[[], WarmStart]],
    config: Any = None,
) -> WarmStart:
    """The provider that ``warmstart`` names or is.

    Parameters
    ----------
    warmstart
        A provider, a :class:`WarmStartResult`, a name (the family's own ``named`` first,
        then the learned names registered for ``family``), a :class:`Solution`, a
        :class:`Trajectory` or an array of states.
    family
        The family's registry key (``"pdg6dof"``, ``"rendezvous"``, ``"robust-rendezvous"``).
    named
        The family's own providers, name -> zero-argument factory.
    config
        The solve's configuration, handed to a learned provider's factory.

    Raises
    ------
    ValueError
        An unknown name, listing the choices.
    """
    if isinstance(warmstart, str) and warmstart not in named:
        learned = registered(family)
        if warmstart not in learned:
            choices = ", ".join([*named, *learned])
            raise ValueError(f"warmstart must be one of {choices}, got {warmstart!r}")
        return learned[warmstart](config)
    return as_provider(warmstart, named)


def checked_solve_arguments(
    method: str,
    methods: Sequence[str],
    instance: Any,
    instance_cls: type,
    config: Any,
    config_cls: type,
) -> Any:
    """The checks every family's ``solve`` makes first: ``method`` among ``methods``,
    ``instance`` and ``config`` of the family's types. Returns ``config``, or the family's
    default ``config_cls()`` when it is None.

    Raises
    ------
    ValueError
        An unknown method, or an instance or configuration of another type
        (:class:`~scpformer.validation.ArgumentTypeError`, also a ``TypeError``).
    """
    if method not in methods:
        raise ValueError(f"method must be one of {', '.join(methods)}, got {method!r}")
    check_type("instance", instance, instance_cls)
    return config_cls() if config is None else check_type("config", config, config_cls)


def warmstart_name(warmstart: Any) -> str:
    """How an error message names a warm start: its name, or its type."""
    return warmstart if isinstance(warmstart, str) else type(warmstart).__name__
