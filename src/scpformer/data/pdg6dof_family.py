"""The 6-DoF powered descent family (T-SCvx paper) as a dataset family.

theta (16,) holds the parameters the paper samples (Sec. IV.A, Table 2), in the order of
:data:`THETA_NAMES`: glideslope and tilt bounds [deg], r0 (3) [U_L], v0 (3) [U_L/U_T],
q0 (4, scalar first), omega0 (3) [deg/U_T], m0 [U_M]. With N nodes, R = 7 N inequality rows
(name-major, :func:`scpformer.problems.pdg6dof.constraints.constraint_index`) and I = iter_max
SCvx iterations, a sample holds:

=============  ===========  ================================================================
field          shape        meaning
=============  ===========  ================================================================
theta          (16,)        instance parameters (see above)
cost           ()           C = -m(t_f) of the returned iterate (Eq. 2)
iterations     ()           subproblem solves k = 1..iterations
tf, t          (), (N,)     final time [U_T] and node times
x, u           (N,14),(N,3) states (r, v, q, omega [rad/U_T], m) and body-frame thrust
guess_*        as x, u, tf  the warm start SCvx started from (cubic-profile guess)
tight_flags    (I, R)       tight rows g >= -tight_tol at SCvx iteration k (row k - 1)
accepted       (I,)         whether iteration k's step was accepted
verified       ()           nonlinear verification passed
max_defect     ()           max |propagated - solution| over the nodes
rotation_deg   ()           rotation about Up applied by the augmentation (0 when solved)
solve_time     ()           s in :func:`~scpformer.problems.pdg6dof.problem.solve`
solver_time    ()           s inside the conic solver
=============  ===========  ================================================================

Rows of ``tight_flags`` past ``iterations``, and every trajectory field of an instance without
a trajectory, hold fill values (False, NaN).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from scpformer.data.family import (
    ConfiguredFamily,
    Field,
    SampleResult,
    dataclass_from_dict,
    package_versions,
)
from scpformer.data.storage import ShardedSamples
from scpformer.problems.pdg6dof.api import solve
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.constants import VehicleConstants
from scpformer.problems.pdg6dof.constraints import CONSTRAINT_NAMES
from scpformer.problems.pdg6dof.guess import cubic_profile_guess
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.problems.pdg6dof.theta import (  # noqa: F401 (also imported from here)
    THETA_NAMES,
    instance_from_theta,
    theta_vector,
)
from scpformer.scp.solution import Solution, Trajectory

RANGE_PRESETS = {
    "feasible": PDGSampleRanges.feasible,
    "table2": PDGSampleRanges.table2,
    "nominal": PDGSampleRanges.nominal,
}


#: Draws of the sampler tried for a mid-flight sample before its base instance counts as
#: failed (a base draw whose cold SCvx does not converge has no trajectory to start from).
MIDFLIGHT_DRAWS = 10


@dataclass(frozen=True, kw_only=True)
class PDG6DoFDataConfig:
    """What a 6-DoF dataset samples and how it solves; defaults: Table 1, Table 2 made feasible.

    ``midflight_nodes = (a, b)`` makes every sample a state along an optimal descent, as a
    re-planning guidance meets them (:mod:`scpformer.guidance.pdg6dof_mpc`): a base instance
    is drawn from ``ranges`` and solved with cold SCvx, a node ``k`` is drawn uniformly from
    ``a .. b``, and the sample is the same descent from the state at node ``k``
    (:meth:`PDGInstance.with_initial_state`), solved cold like any sample. The T-SCvx paper's
    networks see initial states of the sampler only; the states a closed loop re-plans from
    lie elsewhere (lower, slower, lighter); these samples cover them. ``None`` (default): the
    sampler's own initial states.
    """

    ranges: PDGSampleRanges = field(default_factory=PDGSampleRanges.feasible)  # consistent Table 2
    constants: VehicleConstants = field(default_factory=VehicleConstants)  # model (Table 1)
    solver: PDGSolverConfig = field(default_factory=PDGSolverConfig)  # SCvx settings (Table 1)
    midflight_nodes: tuple[int, int] | None = None  # node range of mid-flight states (above)

    def __post_init__(self) -> None:
        if self.midflight_nodes is None:
            return
        nodes = tuple(self.midflight_nodes)
        last = self.solver.n_nodes - 2  # the state at node N - 1 is the landing
        if len(nodes) != 2 or not all(isinstance(k, int | np.integer) for k in nodes) or not (
            1 <= nodes[0] <= nodes[1] <= last
        ):  # fmt: skip
            raise ValueError(
                f"midflight_nodes must be two integers 1 <= a <= b <= N - 2 = {last}, got "
                f"{self.midflight_nodes!r}"
            )
        object.__setattr__(self, "midflight_nodes", (int(nodes[0]), int(nodes[1])))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PDG6DoFDataConfig:
        """Rebuild from :func:`dataclasses.asdict` output (e.g. a manifest's ``config``)."""
        return dataclass_from_dict(cls, data)


@dataclass(frozen=True)
class PDG6DoFFamily(ConfiguredFamily):
    """The 6-DoF powered descent family (a :class:`~scpformer.data.family.DatasetFamily`)."""

    config: PDG6DoFDataConfig = field(default_factory=PDG6DoFDataConfig)
    config_class: ClassVar[type[PDG6DoFDataConfig]] = PDG6DoFDataConfig
    name: ClassVar[str] = "pdg6dof"

    @property
    def n_nodes(self) -> int:
        """N, the number of temporal nodes."""
        return self.config.solver.n_nodes

    def schema(self) -> tuple[Field, ...]:
        n, rows = self.n_nodes, len(CONSTRAINT_NAMES) * self.n_nodes
        iters = self.config.solver.scvx.iter_max
        f64 = "float64"
        return (
            Field(name="theta", dtype=f64, shape=(16,), normalize=True, doc="instance parameters"),
            Field(name="cost", dtype=f64, doc="-m(t_f) of the returned iterate (Eq. 2)"),
            Field(name="iterations", dtype="int64", doc="SCvx subproblem solves"),
            Field(name="tf", dtype=f64, normalize=True, doc="final time t_f [U_T]"),
            Field(name="t", dtype=f64, shape=(n,), doc="node times [U_T]"),
            Field(name="x", dtype=f64, shape=(n, 14), normalize=True, doc="states (Eq. 24)"),
            Field(name="u", dtype=f64, shape=(n, 3), normalize=True, doc="body-frame thrust"),
            Field(name="guess_tf", dtype=f64, doc="final time of the warm start"),
            Field(name="guess_x", dtype=f64, shape=(n, 14), doc="states of the warm start"),
            Field(name="guess_u", dtype=f64, shape=(n, 3), doc="thrust of the warm start"),
            Field(name="tight_flags", dtype="bool", shape=(iters, rows), doc="tight rows per k"),
            Field(name="accepted", dtype="bool", shape=(iters,), doc="step k accepted"),
            Field(name="verified", dtype="bool", doc="nonlinear verification passed"),
            Field(name="max_defect", dtype=f64, doc="max propagated node defect"),
            Field(name="rotation_deg", dtype=f64, doc="augmentation rotation about Up [deg]"),
            Field(name="solve_time", dtype=f64, deterministic=False, doc="s in solve()"),
            Field(name="solver_time", dtype=f64, deterministic=False, doc="s in the conic solver"),
        )

    def versions(self) -> dict[str, str]:
        packages = ("numpy", "scipy", "cvxpy", self.config.solver.scvx.solver)
        return package_versions(packages)

    def warm_up(self) -> None:
        from scpformer.problems.pdg6dof.subproblem import compiled_subproblem

        cfg = self.config.solver
        compiled_subproblem(cfg.n_nodes, cfg.fix_roll, cfg.prox_weight, cfg.scvx.solver)

    def sample(self, rng: np.random.Generator) -> PDGInstance:
        nodes = self.config.midflight_nodes
        return self._base(rng) if nodes is None else self._midflight(rng, nodes)

    def _base(self, rng: np.random.Generator) -> PDGInstance:
        return sample_instances(rng, 1, self.config.ranges, self.config.constants)[0]

    def _midflight(self, rng: np.random.Generator, nodes: tuple[int, int]) -> PDGInstance:
        """A state at a node of ``nodes`` along the cold SCvx optimum of a base draw
        (:class:`PDG6DoFDataConfig`); ``ValueError`` (the sample then fails) when no base draw
        of ``MIDFLIGHT_DRAWS`` converges."""
        low, high = nodes
        for _ in range(MIDFLIGHT_DRAWS):
            base = self._base(rng)
            solution = solve(base, self.config.solver)
            if solution.converged:
                k = int(rng.integers(low, high + 1))
                return base.with_initial_state(solution.trajectory.x[k])
        raise ValueError(
            f"no converged descent in {MIDFLIGHT_DRAWS} base draws to take a mid-flight state from"
        )

    def encode_instance(self, instance: PDGInstance) -> dict[str, Any]:
        return {"theta": theta_vector(instance)}

    def solve(self, instance: PDGInstance) -> SampleResult:
        x_g, u_g, tf_g = cubic_profile_guess(instance, self.n_nodes)
        guess = Trajectory(x=x_g, u=u_g, p=np.array([tf_g]))
        start = time.perf_counter()
        solution = solve(instance, self.config.solver, warmstart=guess)
        solve_time = time.perf_counter() - start
        fields = {
            **self.encode_instance(instance),
            **self._solution_fields(solution),
            "guess_x": x_g,
            "guess_u": u_g,
            "guess_tf": tf_g,
            "rotation_deg": 0.0,
            "solve_time": solve_time,
        }
        return SampleResult(solution.status.value, solution.message, fields, solve_time)

    def _solution_fields(self, solution: Solution) -> dict[str, Any]:
        n, iters = self.n_nodes, self.config.solver.scvx.iter_max
        flags = np.zeros((iters, len(CONSTRAINT_NAMES) * n), dtype=bool)
        accepted = np.zeros(iters, dtype=bool)
        for k, record in enumerate(solution.history[:iters]):
            flags[k], accepted[k] = record.tight_flags, record.accepted
        out: dict[str, Any] = {
            "cost": solution.cost,
            "iterations": solution.iterations,
            "tight_flags": flags,
            "accepted": accepted,
            "solver_time": solution.timing.solver if solution.timing else 0.0,
        }
        if solution.verification is not None:
            out["verified"] = solution.verification.passed
            out["max_defect"] = solution.verification.max_defect
        z = solution.trajectory
        if z is not None:
            out.update(x=z.x, u=z.u, tf=float(z.p[0]), t=solution.t)
        return out


build = PDG6DoFFamily.from_config  # the family from a config dict, or its defaults


SPEC = PDG6DoFFamily.spec(
    "6-DoF free-final-time Mars powered descent solved with SCvx (T-SCvx dataset)"
)


#: Table 2 of the T-SCvx paper, (min, max) per theta component (:data:`THETA_NAMES`) and of K,
#: the SCvx iteration. Its m0 reaches 0.003, below the dry mass: the table records the dataset
#: the paper saw, not a box it sampled.
PAPER_TABLE2: dict[str, tuple[float, float]] = {
    "K": (1.0, 20.0),
    "gamma_gs_deg": (0.0, 90.0),
    "theta_max_deg": (0.0, 359.4),
    "r0_up": (0.003, 9.997),
    "r0_east": (-13.83, 13.83),
    "r0_north": (-13.83, 13.83),
    "v0_up": (-1.998, -0.001),
    "v0_east": (-2.779, 2.779),
    "v0_north": (-2.779, 2.779),
    "q0_w": (-0.996, 1.0),
    "q0_x": (-1.0, 1.0),
    "q0_y": (-1.0, 1.0),
    "q0_z": (-1.0, 0.999),
    "omega0_x_deg": (-89.98, 89.70),
    "omega0_y_deg": (-123.49, 123.49),
    "omega0_z_deg": (-123.49, 123.49),
    "m0": (0.003, 3.0),
}


def table2_ranges(theta: np.ndarray, iterations: np.ndarray) -> dict[str, tuple[float, float]]:
    """(min, max) of K and of every theta component, keyed as :data:`PAPER_TABLE2`.

    ``theta`` is (S, 16) and ``iterations`` (S,), the SCvx solves of each sample (K runs from 1
    to the iteration count). ``ValueError`` when there are no samples.
    """
    theta = np.asarray(theta, dtype=float).reshape(-1, len(THETA_NAMES))
    iterations = np.asarray(iterations).reshape(-1)
    if theta.shape[0] == 0 or theta.shape[0] != iterations.shape[0]:
        raise ValueError(
            f"theta/iterations: need as many rows as iteration counts, at least one; got "
            f"{theta.shape[0]} and {iterations.shape[0]}"
        )
    out = {"K": (1.0, float(iterations.max()))}
    low, high = theta.min(axis=0), theta.max(axis=0)
    out.update({name: (float(low[i]), float(high[i])) for i, name in enumerate(THETA_NAMES)})
    return out


def table2_lines(theta: np.ndarray, iterations: np.ndarray) -> list[str]:
    """Table 2 of these samples beside the paper's: min and max of each parameter."""
    ours = table2_ranges(theta, iterations)
    lines = [f"{'parameter':<14}  {'min':>9} {'max':>9}  {'paper min':>9} {'paper max':>9}"]
    for name, (p_low, p_high) in PAPER_TABLE2.items():
        low, high = ours[name]
        lines.append(f"{name:<14}  {low:>9.4g} {high:>9.4g}  {p_low:>9.4g} {p_high:>9.4g}")
    return lines


def dataset_table2_lines(folder: str | Path) -> list[str]:
    """:func:`table2_lines` of the converged samples of the pdg6dof dataset in ``folder``.

    A header line counts the samples; ``ValueError`` for another family or no converged sample.
    """
    samples = ShardedSamples(folder)
    if samples.manifest.family != PDG6DoFFamily.name:
        raise ValueError(
            f"DIR: Table 2 needs a pdg6dof dataset, {folder} is {samples.manifest.family}"
        )
    solved = np.isin(samples.column("status"), list(PDG6DoFFamily.success_statuses))
    if not solved.any():
        raise ValueError(f"DIR: {folder} holds no converged sample")
    iterations = samples.column("iterations")[solved]
    header = (
        f"Table 2 of {folder}: {int(solved.sum())} converged samples of {len(solved)}; "
        f"SCvx solves per sample {int(iterations.min())}-{int(iterations.max())}"
    )
    return [header, *table2_lines(samples.column("theta")[solved], iterations)]
