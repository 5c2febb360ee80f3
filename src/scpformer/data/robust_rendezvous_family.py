"""The chance-constrained, passively safe rendezvous (robust ART paper) as a dataset family.

Each sample is one instance theta solved by the three-stage procedure the paper uses to build
its datasets (Sec. 4: convex TPBVP -> deterministic collision avoidance -> passive safety in
``RobustDataConfig.mode``), keeping the last feasible stage's trajectory (twin ``ps``) and
recording which stage produced it. The convex TPBVP (twin ``cvx``, the paper's CVX warm start
and lower bound) is stored beside it, with its own Eq. 7 budget, so that ``C_CVX(t_1)`` and
PS-CVX comparisons need no re-solve. Both twins' constraint-to-go is the constraint-violation
budget of Eq. 7 under the dataset's mode, so the ART view
(:class:`~scpformer.data.torch_views.ArtSequenceDataset`) serves robust datasets as it serves
rendezvous ones. The sample's ``status`` is the passive-safety stage's (or the engine's).

theta (13,) holds, in the order of :data:`THETA_NAMES`: the initial RTN state ``x_0,rtn``
[m, m/s] (6), the waypoint code (index in :data:`WAYPOINTS`: ``+T, -T, +R, -R``) and the
target's mean elements (a [m], e, i, RAAN, argp, M [deg]). With N impulses a sample holds the
rendezvous twin fields (:func:`~scpformer.data.rendezvous_family.twin_schema`, prefixes
``ps`` and ``cvx``; ``p_ctg`` is the Eq. 7 budget ``C(t_k)``) and:

============================  ========  =======================================================
field                         shape     meaning
============================  ========  =======================================================
theta                         (13,)     instance parameters (see above)
cost                          ()        cost of the kept trajectory ``sum |dv|_2`` [m/s]
iterations                    ()        SCvx* iterations of the passive-safety stage
t                             (N+1,)    node times [s]
mode                          ()        ``deterministic`` or ``chance``
waypoint                      ()        pre-docking state: ``+T``, ``-T``, ``+R`` or ``-R``
stage                         ()        stage that produced the kept trajectory (``""``: none)
retried_from_tpbvp            ()        stage 3 was re-run from the TPBVP after failing
stage_status_<s>              ()        status of stage ``s`` (``""`` when it did not run)
stage_iterations_<s>          ()        iterations of stage ``s`` (-1 when it did not run)
c_cvx_t1                      ()        ``C_CVX(t_1)``: the TPBVP's Eq. 7 budget at ``t_0``
============================  ========  =======================================================

with ``s`` in :data:`STAGES` (``tpbvp``, ``collision_avoidance``, ``passive_safety``).
Verification of the ``ps`` twin is the robust solver's (linear-model residual, boundary and
safety rows; ``ps_terminal_miss`` is NaN unless the truth replay is switched on in
``solver.verification``); the ``cvx`` twin is not verified (``cvx_verified`` False).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from scpformer.data.family import (
    ConfiguredFamily,
    Field,
    SampleResult,
    dataclass_from_dict,
    package_versions,
)
from scpformer.data.rendezvous_family import TARGET_KEYS, sample_schema, twin_fields
from scpformer.dynamics.uncertainty import UncertaintyModel
from scpformer.problems.rendezvous.scenario import TargetOrbit
from scpformer.problems.rendezvous.subproblems import compiled_subproblem
from scpformer.problems.robust_rendezvous.api import solve
from scpformer.problems.robust_rendezvous.instance import (
    RobustInstance,
    RobustSampleRanges,
    sample_instances,
)
from scpformer.problems.robust_rendezvous.problem import (
    STAGES,
    passive_safety_iterations,
    solve_tpbvp,
)
from scpformer.problems.robust_rendezvous.safety import linear_model, trajectory_violations
from scpformer.problems.robust_rendezvous.scenario import (
    WAYPOINTS,
    RobustScenario,
    RobustSolverConfig,
    check_mode,
    robust_target,
)
from scpformer.problems.robust_rendezvous.subproblem import compiled_safety_subproblem
from scpformer.scp.solution import Solution

THETA_NAMES: tuple[str, ...] = (
    "x0_r_m",
    "x0_t_m",
    "x0_n_m",
    "x0_vr_m_s",
    "x0_vt_m_s",
    "x0_vn_m_s",
    "waypoint_code",
    *(f"target_{key}" for key in TARGET_KEYS),
)
TWINS: tuple[str, ...] = ("ps", "cvx")  # three-stage result and convex TPBVP twins


@dataclass(frozen=True, kw_only=True)
class RobustDataConfig:
    """What a robust dataset samples and how it solves; defaults are robust Tables 1-2."""

    ranges: RobustSampleRanges = field(default_factory=RobustSampleRanges)  # Table 1
    scenario: RobustScenario = field(default_factory=RobustScenario)  # OCP constants
    target: TargetOrbit = field(default_factory=robust_target)  # target mean orbit
    uncertainty: UncertaintyModel = field(default_factory=UncertaintyModel)  # Table 2
    solver: RobustSolverConfig = field(default_factory=RobustSolverConfig)  # SCvx* (Table 1)
    mode: str = "chance"  # passive safety of stage 3: deterministic (X = 0) or chance
    verify: bool = True  # check each stage's trajectory (RobustSolverConfig.verification)

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", check_mode(self.mode))
        object.__setattr__(self, "verify", bool(self.verify))

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RobustDataConfig:
        """Rebuild from :func:`dataclasses.asdict` output (e.g. a manifest's ``config``)."""
        return dataclass_from_dict(cls, data)


def theta_vector(instance: RobustInstance) -> np.ndarray:
    """theta (13,) of ``instance`` in the order of :data:`THETA_NAMES`."""
    code = float(WAYPOINTS.index(instance.waypoint))
    target = instance.target
    return np.array([*instance.x0_rtn, code, *(getattr(target, k) for k in TARGET_KEYS)])


def instance_from_theta(
    theta: np.ndarray,
    scenario: RobustScenario | None = None,
    uncertainty: UncertaintyModel | None = None,
) -> RobustInstance:
    """Inverse of :func:`theta_vector` (validated by :class:`RobustInstance`)."""
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (len(THETA_NAMES),):
        raise ValueError(f"theta must have shape ({len(THETA_NAMES)},), got {theta.shape}")
    code = theta[6]
    if code != round(code) or not 0 <= code < len(WAYPOINTS):
        raise ValueError(f"theta[6] must be a waypoint code 0..{len(WAYPOINTS) - 1}, got {code}")
    target = TargetOrbit(**{k: float(v) for k, v in zip(TARGET_KEYS, theta[7:], strict=True)})
    return RobustInstance(
        x0_rtn=tuple(theta[:6]),
        waypoint=WAYPOINTS[int(code)],
        target=target,
        scenario=scenario or RobustScenario(),
        uncertainty=uncertainty or UncertaintyModel(),
    )


def stage_schema() -> tuple[Field, ...]:
    """Per-stage status and iteration fields, one pair per stage of :data:`STAGES`."""
    return tuple(
        f
        for s in STAGES
        for f in (
            Field(name=f"stage_status_{s}", dtype="str", doc=f"status of stage {s}"),
            Field(name=f"stage_iterations_{s}", dtype="int64", doc=f"iterations of stage {s}"),
        )
    )


def stage_fields(solution: Solution) -> dict[str, Any]:
    """The three-stage bookkeeping of ``solution.extras`` as sample fields."""
    extras = solution.extras
    out: dict[str, Any] = {
        "stage": extras.get("stage") or "",
        "retried_from_tpbvp": bool(extras.get("retried_from_tpbvp", False)),
        "iterations": passive_safety_iterations(solution, missing=-1),
    }
    for s, status in extras.get("stage_status", {}).items():
        out[f"stage_status_{s}"] = status
    for s, iterations in extras.get("stage_iterations", {}).items():
        out[f"stage_iterations_{s}"] = iterations
    return out


@dataclass(frozen=True)
class RobustRendezvousFamily(ConfiguredFamily):
    """The robust rendezvous family (a :class:`~scpformer.data.family.DatasetFamily`)."""

    config: RobustDataConfig = field(default_factory=RobustDataConfig)
    config_class: ClassVar[type[RobustDataConfig]] = RobustDataConfig
    name: ClassVar[str] = "robust-rendezvous"
    twins: ClassVar[tuple[str, ...]] = TWINS  # trajectory twins per sample (ART view)

    @property
    def n_nodes(self) -> int:
        """N, the number of impulses."""
        return self.config.scenario.n_nodes

    def schema(self) -> tuple[Field, ...]:
        cost = "kept trajectory's cost sum |dv|_2 [m/s]"
        iterations = "SCvx* iterations, passive safety"
        return (
            *sample_schema(self.n_nodes, TWINS, cost, iterations),
            Field(name="mode", dtype="str", doc="deterministic or chance"),
            Field(name="waypoint", dtype="str", doc="pre-docking state +T, -T, +R or -R"),
            Field(name="stage", dtype="str", doc="stage that produced the kept trajectory"),
            Field(name="retried_from_tpbvp", dtype="bool", doc="stage 3 re-run from the TPBVP"),
            *stage_schema(),
            Field(name="c_cvx_t1", dtype="int64", doc="C_CVX(t_1): TPBVP's Eq. 7 budget at t_0"),
        )

    def versions(self) -> dict[str, str]:
        return package_versions(("numpy", "scipy", "cvxpy", self.config.solver.scvx.solver))

    def warm_up(self) -> None:
        n, c = self.n_nodes, self.config.solver
        compiled_subproblem("tpbvp", n, max(1, n - 2), c.scvx.solver)
        for rows in sorted({1, c.n_linearized}):  # collision avoidance, passive safety
            compiled_safety_subproblem(n, c.scvx.solver, rows)

    def sample(self, rng: np.random.Generator) -> RobustInstance:
        c = self.config
        return sample_instances(
            rng, 1, c.ranges, scenario=c.scenario, target=c.target, uncertainty=c.uncertainty
        )[0]

    def encode_instance(self, instance: RobustInstance) -> dict[str, Any]:
        return {
            "theta": theta_vector(instance),
            "t": instance.times(),
            "mode": self.config.mode,
            "waypoint": instance.waypoint,
        }

    def solve(self, instance: RobustInstance) -> SampleResult:
        c = self.config
        start = time.perf_counter()
        cvx = solve_tpbvp(instance, c.solver)
        cvx_time = time.perf_counter() - start
        result = solve(instance, dataclasses.replace(c.solver, safety_mode=c.mode), verify=c.verify)
        solve_time = time.perf_counter() - start
        model = linear_model(instance)
        budget = result.extras.get("violation_budget")
        fields = {
            **self.encode_instance(instance),
            **twin_fields("ps", instance, model, result, solve_time - cvx_time, budget),
            **self._cvx_fields(instance, model, cvx, cvx_time),
            **stage_fields(result),
            "cost": result.cost,
        }
        if not np.isfinite(fields.get("ps_terminal_miss", np.nan)):
            fields["ps_max_gap"] = np.nan  # no truth replay ran: no gap was measured
        return SampleResult(result.status.value, result.message, fields, solve_time)

    def _cvx_fields(
        self, instance: RobustInstance, model: Any, cvx: Solution, cvx_time: float
    ) -> dict[str, Any]:
        if cvx.trajectory is None:
            return twin_fields("cvx", instance, model, cvx, cvx_time)
        z = cvx.trajectory
        budget = trajectory_violations(instance, z.x, z.u, self.config.mode)
        fields = twin_fields("cvx", instance, model, cvx, cvx_time, budget)
        fields.pop("cvx_verified", None)  # the TPBVP is not checked against passive safety
        fields["c_cvx_t1"] = int(budget[0])
        return fields


build = RobustRendezvousFamily.from_config  # the family from a config dict, or its defaults


SPEC = RobustRendezvousFamily.spec(
    "passively safe LEO rendezvous: three-stage SCvx* result and convex TPBVP twins"
)
