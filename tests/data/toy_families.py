"""A tiny, fast dataset family for testing the engine without solving anything.

``ToyFamily`` draws theta ~ U(0, 1)^3 and "solves" it in ``sleep`` seconds; instances named by
``hang_index``, ``crash_index`` and ``raise_index`` hang, kill their worker, or raise.
"""

from __future__ import annotations

import os
import time
from dataclasses import asdict, dataclass
from typing import Any, ClassVar

import numpy as np

from scpformer.data.family import FamilySpec, Field, SampleResult, register_family


@dataclass(frozen=True)
class ToyFamily:
    """Implements :class:`scpformer.data.family.DatasetFamily` in microseconds."""

    sleep: float = 0.0
    hang_index: int = -1
    crash_index: int = -1
    raise_index: int = -1
    fail_warm_up: bool = False
    name: ClassVar[str] = "toy"
    success_statuses: ClassVar[frozenset[str]] = frozenset({"ok"})

    def config_dict(self) -> dict[str, Any]:
        return asdict(self)

    def schema(self) -> tuple[Field, ...]:
        return (
            Field(name="theta", dtype="float64", shape=(3,), normalize=True),
            Field(name="value", dtype="float64", normalize=True),
            Field(name="series", dtype="float32", shape=(4, 5)),
            Field(name="solve_time", dtype="float64", deterministic=False),
        )

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def warm_up(self) -> None:
        if self.fail_warm_up:
            raise RuntimeError("toy warm-up failure")

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(size=3)

    def encode_instance(self, instance: np.ndarray) -> dict[str, Any]:
        return {"theta": instance}

    def solve(self, instance: np.ndarray) -> SampleResult:
        start = time.perf_counter()
        time.sleep(self.sleep)
        status = "ok" if instance[0] < 0.8 else "bad"
        series = np.outer(np.arange(4), instance[:1] * np.arange(5)).astype(np.float32)
        fields = {
            "theta": instance,
            "value": float(instance.sum()),
            "series": series,
            "solve_time": time.perf_counter() - start,
        }
        return SampleResult(status, "" if status == "ok" else "theta_0 too large", fields)


@dataclass(frozen=True)
class MisbehavingFamily(ToyFamily):
    """ToyFamily whose chosen instances hang, crash or raise (theta encodes the index)."""

    def solve(self, instance: np.ndarray) -> SampleResult:
        index = _index_of(instance)
        if index == self.hang_index:
            time.sleep(1000.0)
        if index == self.crash_index:
            os._exit(3)
        if index == self.raise_index:
            raise ZeroDivisionError("toy bug")
        return super().solve(instance)


_INDEX_BY_THETA: dict[bytes, int] = {}


def _index_of(instance: np.ndarray) -> int:
    """The instance index of a theta drawn with seed 0 (computed from the streams)."""
    from scpformer.data.executors import instance_rng

    if not _INDEX_BY_THETA:
        for i in range(64):
            _INDEX_BY_THETA[instance_rng(0, i).uniform(size=3).tobytes()] = i
    return _INDEX_BY_THETA.get(np.asarray(instance).tobytes(), -1)


def _build(config: dict | None) -> ToyFamily:
    return ToyFamily(**(config or {}))


TOY_SPEC = FamilySpec(name="toy", summary="toy family for tests", build=_build)
register_family(TOY_SPEC, replace=True)
