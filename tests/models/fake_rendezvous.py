"""A rendezvous dataset family that "solves" instances with random numbers, in microseconds.

Same schema as :class:`scpformer.data.rendezvous_family.RendezvousFamily` (so the ART view
reads it), random values in typical magnitudes; for tests of what reads datasets, not of
what solves them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from scpformer.data.family import SampleResult
from scpformer.data.rendezvous_family import RendezvousFamily

SCALES = {"rtn": 100.0, "roe": 100.0, "dv": 0.01, "rtg": 0.2}


@dataclass(frozen=True)
class FakeRendezvousFamily(RendezvousFamily):
    """:class:`RendezvousFamily`'s schema filled with seeded random values."""

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def warm_up(self) -> None:
        pass

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(size=13)

    def encode_instance(self, instance: np.ndarray) -> dict[str, Any]:
        return {"theta": instance, "t": np.linspace(0.0, 1e4, self.n_nodes + 1)}

    def solve(self, instance: np.ndarray) -> SampleResult:
        rng = np.random.default_rng(int(instance[0] * 2**32))
        status = next(iter(self.success_statuses))
        fields = self.encode_instance(instance)
        for f in self.schema():
            if f.name not in fields:
                fields[f.name] = _value(f, rng, status)
        return SampleResult(status, "", fields)


def _value(field: Any, rng: np.random.Generator, status: str) -> Any:
    suffix = field.name.rsplit("_", 1)[-1]
    if field.dtype == "str":
        return status if suffix == "status" else ""
    if field.dtype == "bool":
        return True
    if field.dtype.startswith("int"):
        return rng.integers(0, 5, size=field.shape)
    if suffix == "ctg":
        return np.cumsum(rng.integers(0, 2, size=field.shape)[::-1])[::-1].astype(float)
    return rng.normal(size=field.shape) * SCALES.get(suffix, 1.0)
