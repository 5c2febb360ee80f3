"""A 6-DoF dataset family that "solves" instances with a fixed formula, in microseconds.

Same schema as :class:`scpformer.data.pdg6dof_family.PDG6DoFFamily` (so the T-SCvx views and
trainer read it) with few nodes and iterations; the tight flags and the solution are smooth
functions of theta and k, so that a network can learn them. For tests of what reads datasets,
not of what solves them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from scpformer.data.family import SampleResult
from scpformer.data.pdg6dof_family import PDG6DoFDataConfig, PDG6DoFFamily
from scpformer.problems.pdg6dof.problem import PDGSolverConfig
from scpformer.scp.scvx import SCvxParameters

N_NODES = 4
ITER_MAX = 5


def fake_config() -> PDG6DoFDataConfig:
    solver = PDGSolverConfig(n_nodes=N_NODES, scvx=SCvxParameters(iter_max=ITER_MAX))
    return PDG6DoFDataConfig(solver=solver)


def fake_flags(theta: np.ndarray, k: int, rows: int) -> np.ndarray:
    """Row r is tight when theta[r % 16] + 0.3 k > 1.5 (about a quarter of the rows)."""
    return theta[np.arange(rows) % 16] + 0.3 * k > 1.5


@dataclass(frozen=True)
class FakePDG6DoFFamily(PDG6DoFFamily):
    """:class:`PDG6DoFFamily`'s schema filled from theta by formulas."""

    config: PDG6DoFDataConfig = field(default_factory=fake_config)

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def warm_up(self) -> None:
        pass

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return rng.normal(size=16)

    def encode_instance(self, instance: np.ndarray) -> dict[str, Any]:
        return {"theta": instance}

    def solve(self, instance: np.ndarray) -> SampleResult:
        theta, n = instance, self.n_nodes
        rows, iters = 7 * n, self.config.solver.scvx.iter_max
        iterations = 2 + int(abs(theta[0]) * 10) % (iters - 1)
        flags = np.zeros((iters, rows), dtype=bool)
        for k in range(1, iterations + 1):
            flags[k - 1] = fake_flags(theta, k, rows)
        nodes = np.linspace(0.0, 1.0, n)[:, None]
        x = np.tanh(theta[:14])[None, :] * (1.0 - nodes) + 0.1 * nodes  # (N, 14)
        u = np.stack([theta[14] * (1 + nodes[:, 0]), theta[15] - nodes[:, 0], nodes[:, 0]], 1)
        fields = {
            "theta": theta,
            "cost": -x[-1, 13],
            "iterations": iterations,
            "tf": 5.0 + theta[1],
            "t": np.linspace(0.0, 5.0 + theta[1], n),
            "x": x,
            "u": u,
            "guess_tf": 5.0,
            "guess_x": np.zeros((n, 14)),
            "guess_u": np.zeros((n, 3)),
            "tight_flags": flags,
            "accepted": np.arange(iters) < iterations,
            "verified": True,
            "max_defect": 0.0,
            "rotation_deg": 0.0,
            "solve_time": 0.0,
            "solver_time": 0.0,
        }
        return SampleResult("converged", "", fields, 0.0)
