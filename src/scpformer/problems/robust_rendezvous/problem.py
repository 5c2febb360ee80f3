"""Solving the robust rendezvous: convex TPBVP, SCvx* on Eq. 17, the three-stage procedure.

Stages (robust ART paper, Section 5, "Dataset generation"):

1. ``"tpbvp"``: the convex two-point boundary value problem (min ``sum |u|``, dynamics and
   boundary states only), the rendezvous family's compiled Problem 1;
2. ``"collision_avoidance"``: SCvx* with the deterministic collision-avoidance constraint
   (``T_safety = 0``, ``X = 0``), warm-started by stage 1;
3. ``"passive_safety"``: SCvx* with passive safety over ``T_safety`` (deterministic, ``X = 0``,
   or chance-constrained with the margin of Eq. 16), warm-started by stage 2 (by stage 1 when
   stage 2 did not converge). Not in the paper: when this run fails, stage 3 is run once more
   from stage 1 (the PS-CVX warm start) and the converged one is kept; on 50 sampled
   instances (seed 1, chance) the stage-2 warm start alone converged on 68% of them, the
   stage-1 warm start alone on 78%, and the two together on 82%. Stage 3 of this procedure
   may take ``RobustSolverConfig.three_stage_iter_max`` (60) solves instead of Table 1's 20.

The final feasible solution is kept: :func:`solve` returns stage 3 when it converged, and
otherwise the latest converged earlier stage, with ``extras["stage"]`` naming the stage that
produced the trajectory; the ``status`` is always that of the requested problem (stage 3), so
``Solution.converged`` is true only for a verified passively safe trajectory.

Dynamics. ``RobustSolverConfig.dynamics = "nonlinear"`` (default) plans in the nonlinear mean
dynamics of :mod:`.plan_dynamics` (SCvx* relinearizes them at every iterate; the TPBVP is
re-solved about its own solution), so that the plans hold in the truth model; ``"stm"`` is
the paper's Eq. 1. ``extras["dynamics"]`` names the model the returned trajectory obeys.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import numpy as np

from scpformer.dynamics.truth import TruthResult, propagate_relative
from scpformer.problems.rendezvous.linear_model import LinearModel
from scpformer.problems.rendezvous.verification import osculating_initial_state
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.plan_dynamics import (
    DynamicsLinearization,
    linearize_dynamics,
)
from scpformer.problems.robust_rendezvous.safety import (
    DriftGeometry,
    SafetyEvaluation,
    drift_geometry,
    evaluate_safety,
    linear_model,
    trajectory_violations,
)
from scpformer.problems.robust_rendezvous.scenario import (
    RobustSolverConfig,
    RobustVerification,
    check_mode,
)
from scpformer.problems.robust_rendezvous.subproblem import compiled_safety_subproblem
from scpformer.problems.robust_rendezvous.tpbvp import (  # noqa: F401 (old import spelling)
    TPBVP_DEFECT_M,
    TPBVP_MAX_SOLVES,
    Boundary,
    boundary,
    solve_tpbvp,
)
from scpformer.scp.conic import start_cold
from scpformer.scp.scvx_star import NonlinearEvaluation, SCvxStar, SubproblemResult
from scpformer.scp.solution import (
    IterationRecord,
    Solution,
    Trajectory,
    Verification,
)
from scpformer.scp.warmstart import WarmStartResult

STAGES = ("tpbvp", "collision_avoidance", "passive_safety")


DEFECT_SCALE_M = 10.0  # g = dynamics defect / this: chi <= eps_feas bounds it by 1 cm [m]


# ======================================================================================
# stages 2-3: SCvx* on Eq. 17
# ======================================================================================
class PassiveSafetyProblem:
    """The CC-OCP of Eq. 1 in the form SCvx* expects (:class:`AugmentedLagrangianProblem`).

    ``z = (x, u)``: ``x`` (N+1, 6) [m], ``u`` (N, 3) [m/s]; ``f0 = sum |u_i|_2``; ``h`` (N,)
    the normalized safety constraints of :mod:`.safety`. With the STM (``config.dynamics =
    "stm"``) there is no ``g``: the linear dynamics and the boundary states are exact
    subproblem constraints. With the nonlinear mean dynamics, ``g`` (6N) is the defect
    ``x_{i+1} - F(x_i + B_i u_i)`` divided by ``DEFECT_SCALE_M`` (so ``chi <= eps_feas`` bounds
    it by a centimetre: the STM-free plan is then accurate to the truth model's ~0.1 m; with
    the defect in metres the ratio test rejected the large, nearly free steps of the
    degenerate fuel cost for millimetres of defect, and SCvx* converged on 13 of 20 CVX-started
    chance instances instead of 16); the subproblem imposes its linearization at the
    reference as a hard constraint (no virtual buffer ``xi``: the linearized dynamics with free
    impulses are always satisfiable, and the defect of an accepted iterate is second order in
    its step), so ``chi`` and the penalized cost see the true defect.
    """

    def __init__(
        self,
        instance: RobustInstance,
        config: RobustSolverConfig,
        mode: str,
        *,
        collision_only: bool = False,
        model: LinearModel | None = None,
    ) -> None:
        self.instance, self.config = instance, config
        self.mode = "deterministic" if collision_only else check_mode(mode)
        self.dynamics = config.dynamics
        self.model = model or linear_model(instance)
        self.geometry: DriftGeometry = drift_geometry(
            instance, 0.0 if collision_only else None, dynamics=config.dynamics
        )
        self.bounds = boundary(instance, self.model, config.dynamics)
        self.n_rows = 1 if collision_only else config.n_linearized
        self.sub = compiled_safety_subproblem(instance.n_nodes, config.scvx.solver, self.n_rows)
        start_cold(self.sub.problem)  # the run's solves reuse one solver object
        Gamma = self.model.Phi @ self.model.B
        self.sub.set_dynamics(self.model.Phi, Gamma, self.bounds.x_init, self.bounds.x_final)

    def safety(self, z: Trajectory, dyn: DynamicsLinearization | None = None) -> SafetyEvaluation:
        """Eqs. 14-16 at ``z`` (drift arcs from the post-impulse states of ``dyn`` if given)."""
        return evaluate_safety(
            self.geometry,
            self.model,
            z.x,
            z.u,
            self.instance,
            self.mode,
            self.n_rows,
            self.config.margin_gradient,
            post_impulse=None if dyn is None else (dyn.y, dyn.B),
        )

    def dynamics_at(self, z: Trajectory) -> DynamicsLinearization:
        """The plan's dynamics linearized at ``z``."""
        return linearize_dynamics(self.instance, self.model, z.x, z.u, self.dynamics)

    def evaluate(self, z: Trajectory) -> NonlinearEvaluation:
        t0 = time.perf_counter()
        dyn = self.dynamics_at(z) if self.dynamics != "stm" else None
        ev = self.safety(z, dyn)
        cost = float(np.linalg.norm(z.u, axis=1).sum())
        return NonlinearEvaluation(
            cost=cost,
            g=np.zeros(0) if dyn is None else dyn.defect.ravel() / DEFECT_SCALE_M,
            h=ev.h,
            linearization=(ev, dyn),
            tight_flags=ev.h >= -self.config.tight_tol,
            time=time.perf_counter() - t0,
        )

    def solve_subproblem(
        self,
        z: Trajectory,
        evaluation: NonlinearEvaluation,
        *,
        lambda_: np.ndarray,
        mu: np.ndarray,
        w: float,
        r: float,
        solver: str,
    ) -> SubproblemResult:
        ev: SafetyEvaluation
        dyn: DynamicsLinearization | None
        ev, dyn = evaluation.linearization
        if dyn is not None:
            self.sub.set_dynamics(dyn.Phi, dyn.Gamma, self.bounds.x_init, self.bounds.x_final,
                                  dyn.f)  # fmt: skip
        scale = self.config.u_trust_scale
        a_x, a_u, c = ev.subproblem_rows(z.x, z.u)  # Eq. 17 rows, margin linearized
        self.sub.set_iterate(
            z.x,
            z.u,
            a_x,
            a_u,
            c,
            mu=mu,
            w=w,
            r=r,
            u_trust_scale=scale,
        )
        res = self.sub.solve(solver)
        if not res.ok:
            return SubproblemResult(False, res.status, None, math.nan, None, None, math.nan,
                                    res.solver_time, message=res.status)  # fmt: skip
        step = max(float(np.abs(res.x - z.x).max()), float(np.abs(res.u - z.u).max()) / scale)
        return SubproblemResult(
            ok=True,
            status=res.status,
            z=Trajectory(x=res.x, u=res.u, p=np.zeros(0)),
            cost=res.cost,
            xi=None,
            zeta=res.zeta,
            step_norm=step,
            solver_time=res.solver_time,
        )

    def verify(self, z: Trajectory) -> Verification:
        """Dynamics residual (of the plan's model), boundary misses, the safety rows and, by
        default (``RobustVerification.truth_replay``), the truth replay of the impulses.

        ``terminal_error``: the replay's miss of the waypoint ``x_f`` at ``t_N``, as norms
        (``position_m``, ``velocity_m_s``) and per RTN component (``r_m`` .. ``vn_m_s``);
        empty without the replay. ``max_defect``: the largest position gap [m] between the
        plan (its mean ROE mapped to RTN to first order) and the replay at the nodes; it holds
        the J2 short-period offset of mean from osculating states (tens of metres at Table 1's
        kilometres), so it is reported, not checked. A replay that fails (e.g. an escaping
        orbit) fails the verification with the error.
        """
        tol = self.config.verification
        dyn = self.dynamics_at(z)
        ev = self.safety(z, dyn if self.dynamics != "stm" else None)
        defect = float(np.abs(dyn.defect).max())
        residual = max(
            defect if self.dynamics == "stm" else 0.0,
            float(np.abs(z.x[0] - self.bounds.x_init).max()),
            float(np.abs(z.x[-1] - self.bounds.x_final).max()),
        )
        worst = float(max(0.0, ev.h.max()))
        node = {"model_residual_m": residual, "dynamics_defect_m": defect, "passive_safety": worst}
        problems = []
        if residual > tol.model_residual_m:
            problems.append(f"model residual {residual:.3g} m > {tol.model_residual_m:.3g} m")
        if self.dynamics != "stm" and defect > tol.dynamics_defect_m:
            problems.append(f"dynamics defect {defect:.3g} m > {tol.dynamics_defect_m:.3g} m")
        if worst > tol.safety_tol:
            problems.append(f"safety violation {worst:.3g} > {tol.safety_tol:.3g}")
        terminal: dict[str, float] = {}
        max_gap = 0.0
        if tol.truth_replay:
            try:
                terminal, max_gap = self._replay(z)
            except (ArithmeticError, RuntimeError, ValueError) as err:
                problems.append(f"truth replay failed: {err}")
                max_gap = math.inf
            else:
                problems += _replay_problems(terminal, tol)
        return Verification(
            passed=not problems,
            terminal_error=terminal,
            max_defect=max_gap,
            node_violations=node,
            path_violations={},
            message="; ".join(problems),
        )

    def _replay(self, z: Trajectory) -> tuple[dict[str, float], float]:
        """Waypoint miss of the truth replay of ``z.u`` and its largest gap to the plan [m]."""
        truth = replay(self.instance, z.u)
        rtn_model = self.model.rtn(z.x)
        return replay_miss(self.instance, truth.rtn[-1]), float(
            np.linalg.norm(truth.rtn[:, :3] - rtn_model[:, :3], axis=1).max()
        )

    def node_times(self, z: Trajectory) -> np.ndarray:
        return self.model.t


def replay(instance: RobustInstance, u: np.ndarray) -> TruthResult:
    """Impulses through the two-body + J2 propagator from the consistent osculating state.

    Uses :func:`scpformer.problems.rendezvous.verification.osculating_initial_state` (it reads only
    ``target``, ``roe0`` and ``scenario.j2``). Outputs the pre-impulse state at every node.
    """
    oe_c, rtn0 = osculating_initial_state(instance)  # type: ignore[arg-type]
    t = instance.times()
    return propagate_relative(oe_c, rtn0, t[:-1], np.asarray(u, dtype=float), t_out=t,
                              j2=instance.scenario.j2)  # fmt: skip


def replay_miss(instance: RobustInstance, final_rtn: np.ndarray) -> dict[str, float]:
    """Miss of the waypoint by the replayed RTN state ``final_rtn`` at ``t_N``: norms
    (``position_m`` [m], ``velocity_m_s`` [m/s]) and RTN components (``r_m`` .. ``vn_m_s``)."""
    miss = np.asarray(final_rtn, dtype=float) - instance.xf_rtn
    terminal = {
        "position_m": float(np.linalg.norm(miss[:3])),
        "velocity_m_s": float(np.linalg.norm(miss[3:])),
    }
    terminal.update({f"{c}_m": float(v) for c, v in zip("rtn", miss[:3], strict=True)})
    terminal.update({f"v{c}_m_s": float(v) for c, v in zip("rtn", miss[3:], strict=True)})
    return terminal


def _replay_problems(terminal: dict[str, float], tol: RobustVerification) -> list[str]:
    """The replay's misses of the waypoint beyond the tolerances, each naming the miss."""
    problems = []
    if terminal["position_m"] > tol.terminal_position_m:
        problems.append(f"truth replay misses the waypoint by {terminal['position_m']:.3g} m "
                        f"> {tol.terminal_position_m:.3g} m")  # fmt: skip
    if terminal["velocity_m_s"] > tol.terminal_velocity_m_s:
        problems.append(f"truth replay misses the waypoint velocity by "
                        f"{terminal['velocity_m_s'] * 1e3:.3g} mm/s > "
                        f"{tol.terminal_velocity_m_s * 1e3:.3g} mm/s")  # fmt: skip
    return problems


def _as_trajectory(warm: Any, n: int) -> Trajectory:
    if isinstance(warm, Solution):
        if warm.trajectory is None:
            raise ValueError(f"warm start has no trajectory (status {warm.status.value})")
        warm = warm.trajectory
    if not isinstance(warm, Trajectory):
        raise ValueError(f"warm start must be a Solution or a Trajectory, got {type(warm)}")
    x, u = np.asarray(warm.x, dtype=float), np.asarray(warm.u, dtype=float)
    if x.shape != (n + 1, 6) or u.shape != (n, 3):
        raise ValueError(f"warm start must have x ({n + 1}, 6) and u ({n}, 3), got {x.shape}, "
                         f"{u.shape}")  # fmt: skip
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(u))):
        raise ValueError("warm start must be finite")
    return Trajectory(x=x, u=u, p=np.zeros(0))


def solve_safety(
    instance: RobustInstance,
    warm: Solution | Trajectory,
    config: RobustSolverConfig | None = None,
    mode: str = "chance",
    *,
    collision_only: bool = False,
    verify: bool = True,
) -> Solution:
    """SCvx* (Table 1) on Eq. 17 from ``warm``; one stage of the procedure.

    ``collision_only`` gives stage 2 (``T_safety = 0``, ``X = 0``); otherwise passive safety in
    ``mode``. ``verify=False`` skips the final check (``verification`` None). Returns the SCvx*
    :class:`Solution` with ``extras``: ``stage``, ``mode``, ``records`` (SCvx* per-iteration
    ``delta_J``, ``chi``, ``w``).
    """
    config = config or RobustSolverConfig()
    mode = check_mode(mode)
    problem = PassiveSafetyProblem(instance, config, mode, collision_only=collision_only)
    if not verify:
        problem.verify = _skip_verify  # type: ignore[method-assign]
    z0 = _as_trajectory(warm, instance.n_nodes)
    result = SCvxStar(config.scvx).solve(problem, z0)
    stage = "collision_avoidance" if collision_only else "passive_safety"
    extras = {
        "stage": stage,
        "mode": problem.mode,
        "dynamics": problem.dynamics,
        "records": [r.__dict__ for r in result.records],
    }
    return replace(result.solution, extras=extras)


def _skip_verify(z: Trajectory) -> None:
    """The verification of a solve asked not to verify: none (never a passed one)."""
    return None


# ======================================================================================
# the three-stage solve
# ======================================================================================
def three_stage(
    instance: RobustInstance, config: RobustSolverConfig, result: WarmStartResult, verify: bool
) -> Solution:
    """The three-stage procedure (the dataset's, module docstring) from the TPBVP's ``result``
    (:class:`~scpformer.problems.robust_rendezvous.warmstart.RobustTpbvpWarmStart`)."""
    stages: dict[str, Solution] = {}
    if result.solution is not None and result.solution.extras.get("stage") == "tpbvp":
        stages["tpbvp"] = result.solution  # kept if passive safety fails
    if result.trajectory is None:
        return _with_record(_assemble(instance, config, stages, "passive_safety"), result)
    mode = config.safety_mode
    warm: Solution | Trajectory = result.trajectory
    ca = solve_safety(instance, warm, config, mode, collision_only=True, verify=verify)
    stages["collision_avoidance"] = ca
    from_ca = ca.converged
    warm = ca if from_ca else warm
    details = {"passive_safety_from": "collision_avoidance" if from_ca else "tpbvp"}
    result = replace(result, record=replace(result.record, details=details))
    config = _three_stage_config(config)  # stage 3 of the procedure gets more solves
    final = solve_safety(instance, warm, config, mode, verify=verify)
    if not final.converged and from_ca:
        retry = solve_safety(instance, stages["tpbvp"], config, mode, verify=verify)
        final = retry if retry.converged else final
        final.extras["retried_from_tpbvp"] = True
    stages["passive_safety"] = final
    return _with_record(_assemble(instance, config, stages, "passive_safety"), result)


def passive_safety_from(
    instance: RobustInstance,
    config: RobustSolverConfig,
    result: WarmStartResult,
    verify: bool,
    *,
    given: bool = False,
) -> Solution:
    """Passive safety (stage 3 alone, SCvx* with Table 1's cap) straight from a warm start's
    ``result``: PS-CVX from the TPBVP, PS-ART from ART. ``given``: the result wraps a solution
    handed in by the caller (never reported as this solve's TPBVP stage)."""
    stages: dict[str, Solution] = {}
    solved = None if given else result.solution
    if solved is not None and solved.extras.get("stage") == "tpbvp":
        stages["tpbvp"] = solved  # the provider's TPBVP, kept if passive safety fails
    if result.trajectory is None:
        if "tpbvp" not in stages:
            raise ValueError(f"warm start has no trajectory: {result.record.reason}")
        return _with_record(_assemble(instance, config, stages, "passive_safety"), result)
    final = solve_safety(instance, result.trajectory, config, config.safety_mode, verify=verify)
    stages["passive_safety"] = final
    return _with_record(_assemble(instance, config, stages, "passive_safety"), result)


def passive_safety_iterations(solution: Solution, missing: int) -> int:
    """SCvx* solves of the passive-safety stage of a :func:`solve` result, ``missing`` when
    that stage did not run.

    ``solution.iterations`` is the same number whenever that stage ran (:func:`_assemble`);
    reading ``extras`` tells the runs where it did not (the TPBVP failed) apart, e.g. as -1 in
    a dataset column.
    """
    return int(solution.extras.get("stage_iterations", {}).get("passive_safety", missing))


def _three_stage_config(config: RobustSolverConfig) -> RobustSolverConfig:
    """``config`` with stage 3's cap raised to ``config.three_stage_iter_max`` solves."""
    iter_max = max(config.scvx.iter_max, config.three_stage_iter_max)
    return replace(config, scvx=replace(config.scvx, iter_max=iter_max))


def _with_record(solution: Solution, result: WarmStartResult) -> Solution:
    """``solution`` with the warm start's record in ``extras["warmstart"]``."""
    return replace(solution, extras={**solution.extras, "warmstart": result.record.to_dict()})


def _assemble(
    instance: RobustInstance,
    config: RobustSolverConfig,
    stages: dict[str, Solution],
    requested: str,
) -> Solution:
    """The final feasible stage's trajectory under the requested stage's status and solve count.

    ``iterations`` goes with ``status``: a passive-safety stage that ends at the cap reports its
    own SCvx* solves (e.g. 20), not those of the TPBVP whose trajectory it falls back to.
    """
    mode = config.safety_mode
    final = stages.get(requested)
    kept = next(
        (name for name in reversed(STAGES) if name in stages and stages[name].converged), None
    )
    source = stages[kept] if kept else (final or stages["tpbvp"])
    status = final.status if final is not None else stages["tpbvp"].status
    if final is None:  # the TPBVP itself failed: the instance or the solver is at fault
        message = f"{stages['tpbvp'].message}; passive-safety stage not attempted"
    elif kept == requested:
        message = final.message
    else:
        message = f"{requested}: {final.message or final.status.value}; kept stage {kept}"
    extras: dict[str, Any] = {
        "stage": kept,
        "mode": mode,
        "dynamics": source.extras.get("dynamics", "stm"),
        "stage_status": {k: s.status.value for k, s in stages.items()},
        "stage_iterations": {k: s.iterations for k, s in stages.items()},
        "stage_wall_s": {k: s.timing.total if s.timing else math.nan for k, s in stages.items()},
    }
    if final is not None:
        for key in ("records", "retried_from_tpbvp"):
            if key in final.extras:
                extras[key] = final.extras[key]
    if source.trajectory is not None:
        x, u = source.trajectory.x, source.trajectory.u
        extras["violation_budget"] = trajectory_violations(instance, x, u, mode,
                                                           dynamics=extras["dynamics"])  # fmt: skip
    history: list[IterationRecord] = source.history
    iterations = final.iterations if final is not None else source.iterations  # with status
    return replace(
        source,
        status=status,
        message=message,
        extras=extras,
        history=history,
        iterations=iterations,
    )
