"""The ISS rendezvous family (ART paper, Sec. 4) as a dataset family.

Each sample is one base instance theta solved as ART trains on it: the convex Problem 2
(twin ``cvx``) and Problem 3 by the SCP of Section 4 (twin ``scp``), which starts from the
warm start named by ``RendezvousDataConfig.warmstart`` (by default the convex solution itself).
With ``RendezvousDataConfig.tpbvp_twin`` (the default) it also holds the convex Problem 1
(twin ``tpbvp``), the reference of the paper's Table 2 and its CVX-TPBVP warm start; datasets
made before that twin existed have ``cvx`` and ``scp`` only and load as they are. The
sample's ``status`` is Problem 3's (or the engine's, e.g. ``timeout``).

theta (13,) holds the instance as sampled, in the order of :data:`THETA_NAMES`: the initial
mean ROE ``a dalpha(t_0)`` (6) [m], the horizon [orbits] and the target's mean elements
(a [m], e, i, RAAN, argp, M [deg]). With N impulses (N + 1 nodes) and twin prefix ``p`` in
:data:`TWINS`, a sample holds:

================  ========  ==================================================================
field             shape     meaning
================  ========  ==================================================================
theta             (13,)     instance parameters (see above)
cost              ()        Problem 3 cost ``sum |dv|_2`` [m/s] (NaN without a solution)
iterations        ()        Problem 3 SCP iterations (subproblem solves)
t                 (N+1,)    node times [s]
p_status          ()        the twin's own solve status (``""`` when it never ran)
p_message         ()        the twin's solve message
p_cost            ()        ``sum |dv|_2`` [m/s]
p_roe             (N+1, 6)  scaled mean ROE ``a dalpha(t_k)`` [m] (Eq. 10 states)
p_rtn             (N+1, 6)  RTN ``Psi(t_k) a dalpha(t_k)`` [m, m/s] (Eq. 9)
p_dv              (N, 3)    impulses in RTN [m/s]
p_rtg             (N+1,)    reward-to-go ``R(t_k)`` [m/s] (Eqs. 4, 20)
p_ctg             (N+1,)    constraint-to-go ``C(t_k)`` [-] (Eqs. 5, 21)
p_verified        ()        nonlinear replay within tolerances (False when not verified)
p_terminal_miss   ()        replay miss of the docking port [m] (NaN when not verified)
p_max_gap         ()        max linear-vs-replay position gap [m] (NaN when not verified)
c_cvx_t1          ()        ``C_CVX(t_1)``, the convex twin's constraint-to-go at ``t_0``
warmstart         ()        name of the SCP's warm start (``convex`` or ``tpbvp``)
ws_roe            (N+1, 6)  the warm start's states [m], the SCP's first reference
ws_cost           ()        the warm start's cost [m/s] (``J_0`` of Eq. 19)
p_solve_time      ()        s in :func:`~scpformer.problems.rendezvous.problem.solve`
p_solver_time     ()        s inside the conic solver
================  ========  ==================================================================

Twin fields of a twin that has no trajectory hold fill values (NaN, -1, False, ``""``).
"""

from __future__ import annotations

import math
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
from scpformer.problems.rendezvous.api import solve
from scpformer.problems.rendezvous.constraints import constraint_to_go, reward_to_go
from scpformer.problems.rendezvous.instance import (
    RendezvousInstance,
    SampleRanges,
    sample_instances,
)
from scpformer.problems.rendezvous.linear_model import LinearModel, linear_model
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    RendezvousSolverConfig,
    TargetOrbit,
)
from scpformer.problems.rendezvous.subproblems import compiled_subproblem
from scpformer.problems.rendezvous.warmstart import RENDEZVOUS_CONVEX as WARMSTARTS
from scpformer.scp.solution import Solution

TARGET_KEYS = ("a_m", "e", "i_deg", "raan_deg", "argp_deg", "M_deg")  # theta's target orbit
THETA_NAMES: tuple[str, ...] = (
    "roe0_da_m",
    "roe0_dlambda_m",
    "roe0_dex_m",
    "roe0_dey_m",
    "roe0_dix_m",
    "roe0_diy_m",
    "horizon_orbits",
    *(f"target_{key}" for key in TARGET_KEYS),
)
TWINS: tuple[str, ...] = ("scp", "cvx", "tpbvp")  # Problem 3, 2 and 1 twins
TWIN_PROBLEM = {"scp": "scp", "cvx": "convex", "tpbvp": "tpbvp"}  # prefix -> solve() problem
STATE_FRAMES = ("roe", "rtn")


@dataclass(frozen=True, kw_only=True)
class RendezvousDataConfig:
    """What a rendezvous dataset samples and how it solves; defaults are the ART Table 1."""

    ranges: SampleRanges = field(default_factory=SampleRanges)  # theta ranges (Table 1)
    scenario: RendezvousScenario = field(default_factory=RendezvousScenario)  # OCP constants
    target: TargetOrbit = field(default_factory=TargetOrbit)  # target (ISS) mean orbit
    solver: RendezvousSolverConfig = field(default_factory=RendezvousSolverConfig)  # SCP
    warmstart: str = "convex"  # initial reference of Problem 3: convex (Problem 2) or tpbvp
    verify: bool = True  # replay every twin through the nonlinear propagator
    tpbvp_twin: bool = True  # also store the Problem 1 (TPBVP) twin

    def __post_init__(self) -> None:
        if self.warmstart not in WARMSTARTS:
            raise ValueError(f"warmstart must be one of {WARMSTARTS}, got {self.warmstart!r}")
        object.__setattr__(self, "verify", bool(self.verify))
        object.__setattr__(self, "tpbvp_twin", bool(self.tpbvp_twin))

    @property
    def twins(self) -> tuple[str, ...]:
        """The twins a sample stores (prefixes of :data:`TWINS`)."""
        return TWINS if self.tpbvp_twin else TWINS[:2]

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RendezvousDataConfig:
        """Rebuild from :func:`dataclasses.asdict` output (e.g. a manifest's ``config``).

        A config without ``tpbvp_twin`` is one of a dataset made before the Problem 1 twin
        existed: it rebuilds with ``tpbvp_twin=False``, the schema that dataset has.
        """
        return dataclass_from_dict(cls, {"tpbvp_twin": False, **data})


def theta_vector(instance: RendezvousInstance) -> np.ndarray:
    """theta (13,) of ``instance`` in the order of :data:`THETA_NAMES`."""
    target = instance.target
    return np.array(
        [*instance.roe0_m, instance.horizon_orbits, *(getattr(target, k) for k in TARGET_KEYS)]
    )


def instance_from_theta(
    theta: np.ndarray, scenario: RendezvousScenario | None = None
) -> RendezvousInstance:
    """Inverse of :func:`theta_vector` (validated by :class:`RendezvousInstance`)."""
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (len(THETA_NAMES),):
        raise ValueError(f"theta must have shape ({len(THETA_NAMES)},), got {theta.shape}")
    target = TargetOrbit(**{k: float(v) for k, v in zip(TARGET_KEYS, theta[7:], strict=True)})
    return RendezvousInstance(
        roe0_m=tuple(theta[:6]),
        horizon_orbits=float(theta[6]),
        target=target,
        scenario=scenario or RendezvousScenario(),
    )


def twin_schema(prefix: str, n: int) -> tuple[Field, ...]:
    """The fields of one trajectory twin (``prefix`` as in :data:`TWINS`), N = ``n``.

    Reused by families whose samples carry the same ART sequences (e.g. robust rendezvous).
    """
    f64 = "float64"
    p = prefix
    return (
        Field(name=f"{p}_status", dtype="str", doc=f"{p}: status of its own solve"),
        Field(name=f"{p}_message", dtype="str", doc=f"{p}: message of its own solve"),
        Field(name=f"{p}_cost", dtype=f64, doc=f"{p}: sum |dv|_2 [m/s]"),
        Field(name=f"{p}_roe", dtype=f64, shape=(n + 1, 6), normalize=True, doc=f"{p}: ROE [m]"),
        Field(name=f"{p}_rtn", dtype=f64, shape=(n + 1, 6), normalize=True, doc=f"{p}: RTN"),
        Field(name=f"{p}_dv", dtype=f64, shape=(n, 3), normalize=True, doc=f"{p}: dv RTN [m/s]"),
        Field(name=f"{p}_rtg", dtype=f64, shape=(n + 1,), doc=f"{p}: reward-to-go [m/s]"),
        Field(name=f"{p}_ctg", dtype=f64, shape=(n + 1,), doc=f"{p}: constraint-to-go"),
        Field(name=f"{p}_verified", dtype="bool", doc=f"{p}: nonlinear replay passed"),
        Field(name=f"{p}_terminal_miss", dtype=f64, doc=f"{p}: replay docking miss [m]"),
        Field(name=f"{p}_max_gap", dtype=f64, doc=f"{p}: max linear-vs-replay gap [m]"),
        Field(name=f"{p}_solve_time", dtype=f64, deterministic=False, doc=f"{p}: s in solve()"),
        Field(name=f"{p}_solver_time", dtype=f64, deterministic=False, doc=f"{p}: s in solver"),
    )


def sample_schema(
    n: int, twins: tuple[str, ...], cost_doc: str, iterations_doc: str
) -> tuple[Field, ...]:
    """The leading fields of a rendezvous sample, N = ``n``: theta, the cost and iterations of
    the solve the sample keeps, the node times and the fields of each of ``twins``."""
    f64 = "float64"
    return (
        Field(name="theta", dtype=f64, shape=(13,), normalize=True, doc="instance parameters"),
        Field(name="cost", dtype=f64, doc=cost_doc),
        Field(name="iterations", dtype="int64", doc=iterations_doc),
        Field(name="t", dtype=f64, shape=(n + 1,), doc="node times [s]"),
        *(f for p in twins for f in twin_schema(p, n)),
    )


def twin_fields(
    prefix: str,
    instance: RendezvousInstance,
    model: LinearModel,
    solution: Solution,
    solve_time: float,
    ctg: np.ndarray | None = None,
) -> dict[str, Any]:
    """One solved twin's values for :func:`twin_schema` (only what exists; the rest is fill).

    ``ctg`` replaces the keep-out constraint-to-go of Eqs. 5, 21 (the robust family passes
    its Eq. 7 violation budget).
    """
    p = prefix
    out: dict[str, Any] = {
        f"{p}_status": solution.status.value,
        f"{p}_message": solution.message,
        f"{p}_cost": solution.cost,
        f"{p}_solve_time": solve_time,
        f"{p}_solver_time": solution.timing.solver if solution.timing else 0.0,
    }
    if solution.verification is not None:
        ver = solution.verification
        out[f"{p}_verified"] = ver.passed
        out[f"{p}_terminal_miss"] = ver.terminal_error.get("position_m", math.nan)
        out[f"{p}_max_gap"] = ver.max_defect
    z = solution.trajectory
    if z is not None and ctg is None:
        out.update(sequence_fields(p, instance.scenario, model, z.x, z.u))
    elif z is not None:
        out.update(art_sequences(p, z.x, model.rtn(z.x), z.u, ctg))
    return out


def sequence_fields(
    prefix: str,
    scenario: RendezvousScenario,
    model: LinearModel,
    roe: np.ndarray,
    dv: np.ndarray,
) -> dict[str, np.ndarray]:
    """States in ROE and RTN (``model``'s Psi), impulses, reward- and constraint-to-go."""
    rtn = model.rtn(roe)
    return art_sequences(prefix, roe, rtn, dv, constraint_to_go(rtn, scenario))


def art_sequences(
    prefix: str, roe: np.ndarray, rtn: np.ndarray, dv: np.ndarray, ctg: np.ndarray
) -> dict[str, np.ndarray]:
    """The ART sequence fields of one twin: states, impulses, ``R(t_k)`` and the given ``C(t_k)``.

    Family-independent: the robust family passes its constraint-violation budget (Eq. 7) as
    ``ctg``, so :class:`~scpformer.data.torch_views.ArtSequenceDataset` serves both families.
    """
    return {
        f"{prefix}_roe": roe,
        f"{prefix}_rtn": rtn,
        f"{prefix}_dv": dv,
        f"{prefix}_rtg": reward_to_go(dv),
        f"{prefix}_ctg": np.asarray(ctg, dtype=float),
    }


@dataclass(frozen=True)
class RendezvousFamily(ConfiguredFamily):
    """The rendezvous family (a :class:`~scpformer.data.family.DatasetFamily`)."""

    config: RendezvousDataConfig = field(default_factory=RendezvousDataConfig)
    config_class: ClassVar[type[RendezvousDataConfig]] = RendezvousDataConfig
    name: ClassVar[str] = "rendezvous"

    @property
    def twins(self) -> tuple[str, ...]:
        """Trajectory twins per sample (ART view)."""
        return self.config.twins

    @property
    def n_nodes(self) -> int:
        """N, the number of impulses."""
        return self.config.scenario.n_nodes

    def schema(self) -> tuple[Field, ...]:
        n, f64 = self.n_nodes, "float64"
        cost, iterations = "Problem 3 cost sum |dv|_2 [m/s]", "Problem 3 SCP iterations"
        return (
            *sample_schema(n, self.twins, cost, iterations),
            Field(name="c_cvx_t1", dtype="int64", doc="C_CVX(t_1): convex twin's ctg at t_0"),
            Field(name="warmstart", dtype="str", doc="SCP warm start: convex or tpbvp"),
            Field(name="ws_roe", dtype=f64, shape=(n + 1, 6), doc="warm start states [m]"),
            Field(name="ws_cost", dtype=f64, doc="warm start cost [m/s]"),
        )

    def versions(self) -> dict[str, str]:
        packages = ("numpy", "scipy", "cvxpy", self.config.solver.scp.solver)
        return package_versions(packages)

    def warm_up(self) -> None:
        sc, solver = self.config.scenario, self.config.solver.scp.solver
        tpbvp = self.config.warmstart == "tpbvp" or self.config.tpbvp_twin
        kinds = {"convex", "scp", "tpbvp" if tpbvp else "convex"}
        for kind in sorted(kinds):
            compiled_subproblem(kind, sc.n_nodes, sc.n_waypoint, solver)

    def sample(self, rng: np.random.Generator) -> RendezvousInstance:
        c = self.config
        return sample_instances(rng, 1, c.ranges, c.scenario, c.target)[0]

    def encode_instance(self, instance: RendezvousInstance) -> dict[str, Any]:
        return {"theta": theta_vector(instance), "t": instance.times()}

    def solve(self, instance: RendezvousInstance) -> SampleResult:
        cvx, cvx_time = self._timed(instance, "convex", None)
        tpbvp = self._timed(instance, "tpbvp", None) if self.config.tpbvp_twin else None
        warm, warm_time = self._warm_start(instance, cvx, cvx_time, tpbvp)
        scp, scp_time = self._timed(instance, "scp", warm)
        model = linear_model(instance)
        fields = {
            **self.encode_instance(instance),
            **twin_fields("cvx", instance, model, cvx, cvx_time),
            **twin_fields("scp", instance, model, scp, scp_time),
            **(twin_fields("tpbvp", instance, model, *tpbvp) if tpbvp else {}),
            **self._warm_fields(warm),
            "cost": scp.cost,
            "iterations": scp.iterations,
        }
        if "cvx_ctg" in fields:
            fields["c_cvx_t1"] = int(fields["cvx_ctg"][0])
        stored = [cvx_time, scp_time] + ([tpbvp[1]] if tpbvp else [])
        separate = warm is not cvx and (tpbvp is None or warm is not tpbvp[0])
        solve_time = sum(stored) + (warm_time if separate else 0.0)
        return SampleResult(scp.status.value, scp.message, fields, solve_time)

    def _timed(
        self, instance: RendezvousInstance, problem: str, warm: Solution | None
    ) -> tuple[Solution, float]:
        start = time.perf_counter()
        c = self.config
        warmstart = None if problem != "scp" else warm if warm is not None else c.warmstart
        solution = solve(instance, c.solver, method=problem, warmstart=warmstart, verify=c.verify)
        return solution, time.perf_counter() - start

    def _warm_start(
        self,
        instance: RendezvousInstance,
        cvx: Solution,
        cvx_time: float,
        tpbvp: tuple[Solution, float] | None,
    ) -> tuple[Solution, float]:
        if self.config.warmstart == "convex":
            return cvx, cvx_time
        if tpbvp is not None:  # the stored Problem 1 twin is the warm start
            return tpbvp
        start = time.perf_counter()
        warm = solve(instance, self.config.solver, method="tpbvp", verify=False)
        return warm, time.perf_counter() - start

    def _warm_fields(self, warm: Solution) -> dict[str, Any]:
        out: dict[str, Any] = {"warmstart": self.config.warmstart, "ws_cost": warm.cost}
        if warm.trajectory is not None:
            out["ws_roe"] = warm.trajectory.x
        return out


build = RendezvousFamily.from_config  # the family from a config dict, or its defaults


SPEC = RendezvousFamily.spec(
    "ISS rendezvous in ROE: TPBVP (Problem 1), convex (Problem 2) and SCP (Problem 3) "
    "twins (ART dataset)"
)
