"""A ``pdg6dof`` dataset family that "solves" instances with known functions, in microseconds.

Same schema as :class:`scpformer.data.pdg6dof_family.PDG6DoFFamily` (so the T-SCvx views and
the lookup tables read it) with few nodes and iterations. theta moves along ``LATENT``
directions only, the solution is affine in theta and the tight flags are a known function
of (theta, k): for tests of what reads the dataset, not of what solves it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from scpformer.data.family import SampleResult
from scpformer.data.pdg6dof_family import PDG6DoFDataConfig, PDG6DoFFamily
from scpformer.problems.pdg6dof.problem import PDGSolverConfig
from scpformer.scp.scvx import SCvxParameters

N_NODES = 3
ITER_MAX = 4
LATENT = 3  # theta = BASE + s @ DIRECTIONS, s ~ U(0, 1)^LATENT
_GEN = np.random.default_rng(1234)
BASE = _GEN.normal(size=16)
DIRECTIONS = _GEN.normal(size=(LATENT, 16))
SOLUTION_MAP = _GEN.normal(size=(16, 17 * N_NODES + 1))  # flat solution = theta @ map


def fake_config() -> PDG6DoFDataConfig:
    scvx = SCvxParameters(iter_max=ITER_MAX)
    return PDG6DoFDataConfig(solver=PDGSolverConfig(n_nodes=N_NODES, scvx=scvx))


def true_solution(theta: np.ndarray) -> np.ndarray:
    """The flat (x, u, t_f) of theta (affine)."""
    return theta @ SOLUTION_MAP


def true_flags(theta: np.ndarray, k: int) -> np.ndarray:
    """Tight flags (7 N,) of iteration k: a threshold on a theta-dependent ramp."""
    rows = 7 * N_NODES
    return np.sin(np.arange(rows) + 3.0 * theta[:LATENT].sum() + k) > 0.3


@dataclass(frozen=True)
class FakePDGFamily(PDG6DoFFamily):
    """:class:`PDG6DoFFamily`'s schema filled with the known functions above."""

    config: PDG6DoFDataConfig = field(default_factory=fake_config)

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def warm_up(self) -> None:
        pass

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return BASE + rng.uniform(size=LATENT) @ DIRECTIONS

    def encode_instance(self, instance: np.ndarray) -> dict[str, Any]:
        return {"theta": instance}

    def solve(self, instance: np.ndarray) -> SampleResult:
        n = N_NODES
        flat = true_solution(instance)
        iterations = 2 + int(instance[0] * 100) % (ITER_MAX - 1)  # 2..ITER_MAX
        flags = np.zeros((ITER_MAX, 7 * n), dtype=bool)
        for k in range(1, iterations + 1):
            flags[k - 1] = true_flags(instance, k)
        fields = {
            "theta": instance,
            "cost": -1.0,
            "iterations": iterations,
            "tf": flat[-1],
            "t": np.linspace(0.0, 1.0, n),
            "x": flat[: 14 * n].reshape(n, 14),
            "u": flat[14 * n : 17 * n].reshape(n, 3),
            "guess_tf": 1.0,
            "guess_x": np.zeros((n, 14)),
            "guess_u": np.zeros((n, 3)),
            "tight_flags": flags,
            "accepted": np.arange(ITER_MAX) < iterations,
            "verified": True,
            "max_defect": 0.0,
            "rotation_deg": 0.0,
            "solve_time": 0.0,
            "solver_time": 0.0,
        }
        return SampleResult("converged", "", fields)
