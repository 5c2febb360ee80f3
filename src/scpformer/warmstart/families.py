"""What ART inference needs to know about a problem family, batched over instances.

For each family: the discrete dynamics in scaled mean ROE (the rendezvous: ``x_{k+1} = Phi_k
(x_k + B_k u_k)`` with the STM and control input matrix of its
:class:`~scpformer.problems.rendezvous.linear_model.LinearModel`, ART paper Eq. 10; the robust
family: its plan's dynamics, the robust paper's Eq. 1 or, by default, the nonlinear
mean-element flow its SCvx* plans and its datasets obey), the map ``Psi_k`` to the RTN frame
(ART paper Eq. 9), the instantaneous constraint
violation ``C_k`` that decreases the constraint-to-go (ART paper Eqs. 5, 21: keep-out zone;
robust paper Eq. 7: passive safety with the chance margin), the target-state token of the
robust paper (the waypoint's relative state) and the convex warm start that sets
``R(t_1) = -J_CVX`` and serves as the fallback.

A :class:`Batch` holds the instances' matrices stacked, so that the generation loop of
:mod:`scpformer.warmstart.art` advances every instance with one ``einsum`` per step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from scpformer.problems.rendezvous.constraints import CTG_TOL, constraint_to_go, keep_out_slack
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.linear_model import LinearModel, linear_model
from scpformer.problems.rendezvous.warmstart import RendezvousConvexWarmStart
from scpformer.scp.warmstart import WarmStart, check_instance

if TYPE_CHECKING:  # the robust family is imported when used: a rendezvous solve needs none of it
    from scpformer.problems.robust_rendezvous.instance import RobustInstance
    from scpformer.problems.robust_rendezvous.safety import DriftGeometry

ART_FAMILIES = ("rendezvous", "robust-rendezvous")
ART_FRAMES = ("rtn", "roe")


@dataclass(frozen=True)
class Batch:
    """Stacked linear models of B instances with N impulses each."""

    instances: tuple[Any, ...]
    models: tuple[LinearModel, ...]
    Phi: np.ndarray  # (B, N, 6, 6) STM Phi(t_{k+1}, t_k)
    B: np.ndarray  # (B, N, 6, 3) control input matrix [s]
    Psi: np.ndarray  # (B, N+1, 6, 6) scaled ROE [m] -> RTN [m, m/s]
    x0: np.ndarray  # (B, 6) initial ROE [m]
    x_target: np.ndarray | None  # (B, 6) ROE of the target-state token (robust), or None
    groups: tuple[tuple[np.ndarray, Any], ...]  # (indices, shared constraint data) per group

    @property
    def n_steps(self) -> int:
        """N, the number of impulses."""
        return self.Phi.shape[1]

    def step(self, k: int, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``x_{k+1} = Phi_k (x_k + B_k u_k)`` (Eq. 10) for every instance, (B, 6) [m]."""
        y = x + np.einsum("bij,bj->bi", self.B[:, k], u)
        return np.einsum("bij,bj->bi", self.Phi[:, k], y)

    def to_frame(self, k: int, x: np.ndarray, frame: str) -> np.ndarray:
        """ROE ``x`` (B, 6) at node ``k`` in ``frame``: ``Psi_k x`` (Eq. 9) or ``x`` itself."""
        return np.einsum("bij,bj->bi", self.Psi[:, k], x) if frame == "rtn" else x

    def from_frame(self, k: int, state: np.ndarray, frame: str) -> np.ndarray:
        """Inverse of :meth:`to_frame` (``Psi_k`` is invertible)."""
        if frame != "rtn":
            return state
        return np.linalg.solve(self.Psi[:, k], state[..., None])[..., 0]


def _grouped(values: Sequence[Any]) -> list[tuple[np.ndarray, Any]]:
    """Indices of equal values, in first-seen order (e.g. instances sharing a scenario)."""
    groups: dict[Any, list[int]] = {}
    for i, value in enumerate(values):
        groups.setdefault(value, []).append(i)
    return [(np.array(idx), value) for value, idx in groups.items()]


def _stack(
    instances: Sequence[Any],
    models: list[LinearModel],
    x0: np.ndarray,
    x_target: np.ndarray | None,
    groups: list[tuple[np.ndarray, Any]],
) -> Batch:
    """The :class:`Batch` of ``instances`` (one N for all)."""
    n = {m.Phi.shape[0] for m in models}
    if len(n) != 1:
        raise ValueError(f"instances must have one number of impulses N, got {sorted(n)}")
    return Batch(
        instances=tuple(instances),
        models=tuple(models),
        Phi=np.stack([m.Phi for m in models]),
        B=np.stack([m.B for m in models]),
        Psi=np.stack([m.Psi for m in models]),
        x0=x0,
        x_target=x_target,
        groups=tuple(groups),
    )


@dataclass(frozen=True)
class RendezvousArtFamily:
    """The ISS rendezvous of the ART paper: keep-out constraint-to-go (Eqs. 5, 21)."""

    name: str = "rendezvous"
    has_target: bool = False

    def batch(self, instances: Sequence[RendezvousInstance]) -> Batch:
        for instance in instances:
            check_instance(instance, RendezvousInstance, self.name)
        models = [linear_model(instance) for instance in instances]
        x0 = np.stack([instance.roe0 for instance in instances])
        groups = _grouped([instance.scenario for instance in instances])
        return _stack(instances, models, x0, None, groups)

    def transition(
        self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``C_k`` (:meth:`violations`) and ``x_{k+1}`` through the STM (:meth:`Batch.step`)."""
        return self.violations(batch, k, x, u), batch.step(k, x, u)

    def violations(self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``C_k`` of Eq. 21: 1 where node ``k <= N_wp`` lies inside the keep-out zone, (B,).

        No node once the waypoint is passed (a remaining problem of the final approach:
        ``RendezvousScenario.n_keep_out`` is 0), as in
        :func:`~scpformer.problems.rendezvous.constraints.constraint_to_go`.
        """
        flags = np.zeros(x.shape[0], dtype=int)
        rtn = batch.to_frame(k, x, "rtn")
        for idx, scenario in batch.groups:
            if k < scenario.n_keep_out:
                flags[idx] = keep_out_slack(rtn[idx], scenario) < -CTG_TOL
        return flags

    def trajectory_ctg(self, instance: RendezvousInstance, model: LinearModel, x: np.ndarray,
                       u: np.ndarray) -> float:  # fmt: skip
        """``C(t_1)`` of a whole trajectory (Eqs. 5, 21)."""
        return float(constraint_to_go(model.rtn(x), instance.scenario)[0])

    def fallback(self, config: Any = None) -> WarmStart:
        """The convex Problem 2 (the ART paper's CVX warm start and ``J_CVX``)."""
        return RendezvousConvexWarmStart("convex", config)


@dataclass(frozen=True)
class _RobustGroup:
    """Instances sharing one uncertainty model, target orbit and scenario (one linear model):
    their drift geometry, stacked per node."""

    instance: RobustInstance  # representative (uncertainty model, target orbit, node times)
    geometry: tuple[DriftGeometry, ...]  # each instance's drift arcs (as its solve sees them)


@dataclass(frozen=True)
class RobustArtFamily:
    """The chance-constrained rendezvous of the robust paper: Eq. 7 budget, target token.

    ``dynamics`` is the plan model the rollout advances with and the constraint-to-go is
    evaluated in (``RobustSolverConfig.dynamics``): the robust paper's Sec. 3 "dynamics model
    available onboard" is taken as the model the SCvx* plans and the datasets' trajectories
    obey. With the default ``"nonlinear"`` plans, a rollout through the first-order STM instead
    drifts tens of metres from the plan it imitates: the dataset's own optimal impulses, rolled
    out through the STM, violate passive safety at 7 nodes in median and pass the post hoc
    check on 19% of 200 chance-mode samples (seed 0); through the plan's dynamics, at none and
    on 76% (``benchmarks/robust_art_rollout_model.py``).
    """

    mode: str = "chance"
    dynamics: str = "nonlinear"  # plan model: mean-element flow (nonlinear) or the J2 STM (stm)
    name: str = "robust-rendezvous"
    has_target: bool = True

    def __post_init__(self) -> None:
        from scpformer.problems.robust_rendezvous.scenario import DYNAMICS, check_mode

        check_mode(self.mode)
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"dynamics must be one of {', '.join(DYNAMICS)}, got "
                             f"{self.dynamics!r}")  # fmt: skip

    def batch(self, instances: Sequence[RobustInstance]) -> Batch:
        from scpformer.problems.robust_rendezvous.instance import RobustInstance
        from scpformer.problems.robust_rendezvous.safety import drift_geometry
        from scpformer.problems.robust_rendezvous.tpbvp import boundary

        for instance in instances:
            check_instance(instance, RobustInstance, self.name)
        models = [linear_model(instance) for instance in instances]
        bounds = [boundary(instance, model) for instance, model in zip(instances, models,
                                                                          strict=True)]  # fmt: skip
        geometry = [drift_geometry(instance, dynamics=self.dynamics) for instance in instances]
        groups = []
        shared = [(i.uncertainty, i.target, i.scenario) for i in instances]  # one model per group
        for idx, _ in _grouped(shared):
            group = _RobustGroup(instances[idx[0]], tuple(geometry[i] for i in idx))
            groups.append((idx, group))
        x0 = np.stack([b.x_init for b in bounds])
        x_target = np.stack([b.x_final for b in bounds])
        return _stack(instances, models, x0, x_target, groups)

    def transition(
        self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``C_k`` (:meth:`violations`) and ``x_{k+1}`` in the plan's dynamics
        (:func:`~scpformer.problems.robust_rendezvous.plan_dynamics.plan_step`), from one
        step of the dynamics."""
        x_next, post = self._advance(batch, k, x, u)
        return self._flags(batch, k, x, u, post), x_next

    def violations(self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``C_k`` of Eq. 7 at node ``k`` (post-maneuver drift with the chance margin), (B,).

        Node ``k``'s constraint depends on ``(x_k, u_k)`` only (its covariance of Eq. 14 is
        local), so each instance is evaluated as a one-node trajectory by
        :func:`~scpformer.problems.robust_rendezvous.safety.node_violation_flags`, its drift
        arc starting from the post-impulse state of the plan's dynamics (the input matrix
        passed beside it is the STM's: a flag needs no derivative).
        """
        return self._flags(batch, k, x, u, self._advance(batch, k, x, u)[1])

    def _flags(
        self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray, post: np.ndarray
    ) -> np.ndarray:
        """:meth:`violations` with the post-impulse states ``post`` (B, 6) [m] given."""
        from scpformer.problems.robust_rendezvous.safety import node_violation_flags

        flags = np.zeros(x.shape[0], dtype=int)
        for idx, group in batch.groups:
            for i, geometry in zip(idx, group.geometry, strict=True):
                model = LinearModel(t=np.zeros(2), oe=np.zeros((2, 6)), Phi=batch.Phi[[i], k],
                                    B=batch.B[[i], k], Psi=batch.Psi[[i], k])  # fmt: skip
                flags[i] = node_violation_flags(_node(geometry, k), model, x[[i]], u[[i]],
                                                group.instance, self.mode,
                                                post_impulse=(post[[i]], model.B))[0]  # fmt: skip
        return flags

    def _advance(
        self, batch: Batch, k: int, x: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """States at node ``k + 1`` and post-impulse states at node ``k``, (B, 6) each [m]."""
        from scpformer.problems.robust_rendezvous.plan_dynamics import plan_step

        x_next, post = np.empty_like(x), np.empty_like(x)
        for idx, group in batch.groups:
            x_next[idx], post[idx] = plan_step(group.instance, batch.models[idx[0]], k, x[idx],
                                               u[idx], self.dynamics)  # fmt: skip
        return x_next, post

    def trajectory_ctg(self, instance: RobustInstance, model: LinearModel, x: np.ndarray,
                       u: np.ndarray) -> float:  # fmt: skip
        """``C(t_1)`` of a whole trajectory (Eq. 7 budget)."""
        from scpformer.problems.robust_rendezvous.safety import trajectory_violations

        return float(trajectory_violations(instance, x, u, self.mode, dynamics=self.dynamics)[0])

    def fallback(self, config: Any = None) -> WarmStart:
        """The convex TPBVP (the robust paper's CVX warm start and ``J_CVX``)."""
        from scpformer.problems.robust_rendezvous.warmstart import RobustTpbvpWarmStart

        return RobustTpbvpWarmStart(config, self.mode)


def _node(geometry: DriftGeometry, k: int) -> DriftGeometry:
    """The drift geometry of node ``k`` alone (every per-node array sliced to ``[k:k+1]``)."""
    per_node = ("Phi", "Psi", "G", "E", "use_ae", "t", "oe_nodes", "qns_nodes")
    return replace(geometry, **{name: getattr(geometry, name)[k : k + 1] for name in per_node})


def art_family(
    name: str, mode: str = "chance", dynamics: str = "nonlinear"
) -> RendezvousArtFamily | RobustArtFamily:
    """The family adapter of ``name`` (``mode``, ``dynamics``: passive safety and plan model of
    the robust family; the rendezvous family's model is the STM of its problem)."""
    families: dict[str, Callable[[], Any]] = {
        "rendezvous": RendezvousArtFamily,
        "robust-rendezvous": lambda: RobustArtFamily(mode, dynamics),
    }
    if name not in families:
        raise ValueError(f"family must be one of {ART_FAMILIES}, got {name!r}")
    return families[name]()
