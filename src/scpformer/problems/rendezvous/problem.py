"""The rendezvous family: linear model, constraints, Problems 1-3, the SCP and verification.

Notation (ART paper, Section 4; nodes as in :mod:`.scenario`)
-------------------------------------------------------------
* ``x_k = a dalpha(t_k)`` [m]: scaled MEAN quasi-nonsingular ROE before the impulse at ``t_k``;
  ``dv_k`` [m/s]: impulse in RTN at ``t_k``, ``k = 0..N-1``.
* Dynamics (Eq. 10): ``x_{k+1} = Phi(dt, t_k) (x_k + B(t_k) dv_k)`` with the J2 STM of
  Koenig et al. (2017) and the impulsive input matrix ``B``, both evaluated on the target's
  mean orbit propagated with the first-order secular J2 rates.
* RTN (Eq. 9): ``dchi_k ~= Psi(t_k) x_k`` (servicer relative to the target, rotating frame).
* Keep-out zone (Eq. 14): ``|E_koz D Psi_k x_k|_2 >= 1`` for ``k = 0..N_wp``; linearized at the
  reference ``x_bar`` as ``a_k^T x_k >= b_k`` (Eqs. 15-16).
* Approach cone (Eq. 13) for ``k = N_wp..N-1``; waypoint at ``N_wp``; docking at ``N``.

Model fidelity. The plan lives in a first-order model of MEAN ROE; the verification replays the
impulses through the nonlinear two-body + J2 propagator of OSCULATING states
(:func:`scpformer.dynamics.truth.propagate_relative`). The mean-to-osculating offset of the
initial state is removed by :func:`osculating_initial_state`; what remains and is measured
(``Verification.max_defect``) is the short-period J2 motion and the truncation of the model.
"""

from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, Literal

import numpy as np

from scpformer.dynamics.mean_elements import average_qns
from scpformer.dynamics.orbits import (
    eci_to_rtn,
    j2_secular_rates,
    oe_to_eci,
    oe_to_qns,
    propagate_kepler,
    propagate_mean_j2,
    qns_to_oe,
    wrap_to_pi,
)
from scpformer.dynamics.roe import (
    control_input_matrix,
    psi_matrix,
    roe_to_oe,
    stm_j2,
    stm_kepler,
)
from scpformer.dynamics.truth import TruthResult, propagate_relative
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.scenario import (
    RendezvousScenario,
    RendezvousSolverConfig,
    SCPParameters,
    VerificationTolerances,
)
from scpformer.problems.rendezvous.subproblems import (
    INACCURATE,
    RendezvousSubproblem,
    SubproblemSolution,
    compiled_subproblem,
)
from scpformer.scp.solution import (
    IterationRecord,
    Solution,
    Status,
    Timing,
    Trajectory,
    Verification,
    verified_status,
)
from scpformer.validation import check_type

ProblemKind = Literal["tpbvp", "convex", "scp"]
PROBLEMS = ("tpbvp", "convex", "scp")
WARMSTARTS = ("tpbvp", "convex")
CTG_TOL = 1e-6  # constraint-to-go: a node counts as violating when |E_koz dr| < 1 - CTG_TOL


# ======================================================================================
# linear model (Eqs. 9-10), vectorized over the horizon
# ======================================================================================
@dataclass(frozen=True)
class LinearModel:
    """Discrete linear ROE model of one instance, every node at once."""

    t: np.ndarray  # (N+1,) node times [s]
    oe: np.ndarray  # (N+1, 6) mean target elements (a, e, i, raan, argp, M) at the nodes
    Phi: np.ndarray  # (N, 6, 6) STM Phi(dt, t_k)
    B: np.ndarray  # (N, 6, 3) control input matrix B(t_k) [s]
    Psi: np.ndarray  # (N+1, 6, 6) ROE [m] -> RTN [m, m/s]

    def rollout(self, x0: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """States ``x_k`` (N+1, 6) [m] from ``x_0`` under the impulses ``dv`` (N, 3) (Eq. 10)."""
        kicks = np.einsum("kij,kj->ki", self.B, dv)
        x = np.empty((self.t.size, 6))
        x[0] = x0
        for k in range(self.t.size - 1):  # a recursion: inherently sequential
            x[k + 1] = self.Phi[k] @ (x[k] + kicks[k])
        return x

    def rtn(self, x: np.ndarray) -> np.ndarray:
        """Relative RTN states ``Psi(t_k) x_k`` (N+1, 6) [m, m/s] (Eq. 9)."""
        return np.einsum("kij,kj->ki", self.Psi, x)

    def residual(self, x: np.ndarray, dv: np.ndarray) -> float:
        """``max |x_{k+1} - Phi_k (x_k + B_k dv_k)|`` [m], how well ``(x, dv)`` obeys Eq. 10."""
        pred = np.einsum("kij,kj->ki", self.Phi, x[:-1] + np.einsum("kij,kj->ki", self.B, dv))
        return float(np.abs(x[1:] - pred).max())


def linear_model(instance: RendezvousInstance) -> LinearModel:
    """Build the STMs, input matrices and ``Psi`` at all nodes (vectorized, ~2 ms at N = 100)."""
    t = instance.times()
    dt = t[1] - t[0]
    oe0 = instance.target.oe.to_array()
    if instance.scenario.j2:
        oe = propagate_mean_j2(oe0, t)
        Phi = stm_j2(oe[:-1], dt)
    else:
        oe = propagate_kepler(oe0, t)
        Phi = stm_kepler(oe[:-1], dt)
    return LinearModel(t=t, oe=oe, Phi=Phi, B=control_input_matrix(oe[:-1]), Psi=psi_matrix(oe))


@dataclass(frozen=True)
class BoundaryData:
    """Boundary conditions and cone rows of Problems 1-3 in ROE form."""

    x_init: np.ndarray  # (6,) x_0 [m]
    x_dock: np.ndarray  # (6,) Psi_N^{-1} (dr_dp, 0) [m]
    x_wp: np.ndarray  # (6,) Psi_{N_wp}^{-1} (dr_wp, 0) [m]
    cone_A: np.ndarray  # (n_cone, 3, 6) D Psi_k, k = N_wp..N-1 (Eq. 13)
    cone_c: np.ndarray  # (n_cone, 6) n^T D Psi_k / cos gamma
    cone_b: np.ndarray  # (3,) -apex
    cone_d: float  # -n^T apex / cos gamma


def boundary_data(instance: RendezvousInstance, model: LinearModel) -> BoundaryData:
    """Eqs. 12-13 with ``Psi x = y`` solved for ``x`` (``Psi`` is invertible)."""
    sc = instance.scenario
    kw, n = sc.n_waypoint, sc.n_nodes
    axis, apex = np.asarray(sc.approach_axis), sc.cone_vertex_m
    cos_g = math.cos(math.radians(sc.cone_half_angle_deg))
    A = model.Psi[kw:n, :3, :]
    return BoundaryData(
        x_init=instance.roe0,
        x_dock=np.linalg.solve(model.Psi[n], np.r_[sc.dock_port_m, 0.0, 0.0, 0.0]),
        x_wp=np.linalg.solve(model.Psi[kw], np.r_[sc.waypoint_m, 0.0, 0.0, 0.0]),
        cone_A=A,
        cone_c=np.einsum("r,krj->kj", axis, A) / cos_g,
        cone_b=-apex,
        cone_d=float(-axis @ apex / cos_g),
    )


# ======================================================================================
# constraints, keep-out linearization, reward- and constraint-to-go
# ======================================================================================
def keep_out_cut(
    Psi: np.ndarray, scenario: RendezvousScenario, x_ref: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Linearized keep-out constraint ``a_k^T x_k >= b_k`` at the reference (Eqs. 15-16).

    ``a_k = M_k x_bar_k`` and ``b_k = sqrt(x_bar_k^T M_k x_bar_k)`` with
    ``M_k = Psi_k^T E_koz^T E_koz Psi_k``. Since ``f(x) = |E_koz D Psi_k x|_2`` is convex and
    ``a_k^T x / b_k`` is its first-order expansion at ``x_bar_k``, ``a_k^T x >= b_k`` implies
    ``f(x) >= 1``: the cut is the tangent half-space of the ellipsoid at the radial projection
    of the reference, a conservative (sufficient) condition.

    Parameters
    ----------
    Psi
        ``Psi(t_k)`` (K, 6, 6) at the keep-out nodes.
    scenario
        Supplies ``E_koz``.
    x_ref
        Reference ROE ``x_bar_k`` (K, 6) [m].

    Returns
    -------
    a, b
        (K, 6) [1/m] and (K,) [-].
    """
    ED = np.einsum("rs,ksj->krj", scenario.E_koz, Psi[:, :3, :])  # E_koz D Psi_k, (K, 3, 6)
    y = np.einsum("krj,kj->kr", ED, x_ref)  # E_koz dr_bar, (K, 3)
    a = np.einsum("kr,krj->kj", y, ED)
    return a, np.linalg.norm(y, axis=1)


def keep_out_slack(r: np.ndarray, scenario: RendezvousScenario) -> np.ndarray:
    """``|E_koz dr| - 1`` (>= 0 outside the keep-out zone) for positions ``(..., >=3)`` [m]."""
    return scenario.koz_metric(np.asarray(r)[..., :3]) - 1.0


def cone_slack(r: np.ndarray, scenario: RendezvousScenario) -> np.ndarray:
    """``n^T d - |d| cos gamma`` [m], ``d = dr - apex`` (>= 0 inside the cone of Eq. 13).

    Eq. 13 multiplied by ``cos gamma``: ``|d| (cos angle(d, n) - cos gamma)``, a length.
    """
    d = np.asarray(r)[..., :3] - scenario.cone_vertex_m
    cos_g = math.cos(math.radians(scenario.cone_half_angle_deg))
    return d @ np.asarray(scenario.approach_axis) - np.linalg.norm(d, axis=-1) * cos_g


def constraint_index(scenario: RendezvousScenario) -> list[tuple[str, int]]:
    """Stable ``(name, node)`` label of every inequality row (order of the tight flags)."""
    kw, n = scenario.n_waypoint, scenario.n_nodes
    return [("keep_out", k) for k in range(kw + 1)] + [("approach_cone", k) for k in range(kw, n)]


def tight_flags(rtn: np.ndarray, scenario: RendezvousScenario, tol: float) -> np.ndarray:
    """Rows of :func:`constraint_index` whose slack is at most ``tol`` ([-] keep-out, [m] cone).

    ``rtn`` holds the relative states of all nodes, (N+1, >=3).
    """
    kw, n = scenario.n_waypoint, scenario.n_nodes
    koz = keep_out_slack(rtn[: kw + 1], scenario) <= tol
    return np.concatenate([koz, cone_slack(rtn[kw:n], scenario) <= tol])


def reward_to_go(dv: np.ndarray) -> np.ndarray:
    """``R(t_k) = -sum_{j >= k} |dv_j|_2`` (Eqs. 4, 20), (N+1,) with ``R(t_N) = 0`` [m/s]."""
    norms = np.linalg.norm(np.asarray(dv, dtype=float), axis=1)
    return -np.concatenate([np.cumsum(norms[::-1])[::-1], [0.0]])


def constraint_to_go(
    rtn: np.ndarray, scenario: RendezvousScenario, tol: float = CTG_TOL
) -> np.ndarray:
    """``C(t_k) = sum_{j >= k} C_j`` (Eqs. 5, 21), (N+1,) integers.

    ``C_j = 1`` when node ``j <= N_wp`` (where the keep-out constraint applies) has
    ``|E_koz dr_j|_2 < 1 - tol``; ``tol`` keeps a point on the boundary (an active cut, within
    the conic solver's accuracy) from counting as a violation.

    Parameters
    ----------
    rtn
        Relative RTN states (N+1, >=3) [m] of any trajectory (e.g. ``LinearModel.rtn(x)``).
    scenario
        Supplies the keep-out ellipsoid and ``N_wp``.
    tol
        Boundary tolerance on ``|E_koz dr|``.
    """
    rtn = np.asarray(rtn, dtype=float)
    flags = np.zeros(rtn.shape[0], dtype=int)
    kw = scenario.n_waypoint
    flags[: kw + 1] = keep_out_slack(rtn[: kw + 1], scenario) < -tol
    return np.cumsum(flags[::-1])[::-1].copy()


# ======================================================================================
# verification: replay through the nonlinear propagator
# ======================================================================================
def _orbit_averaged_qns(
    oe_c: np.ndarray, oe_d: np.ndarray, periods: list[float], samples: int
) -> list[np.ndarray]:
    """One-orbit averages of both spacecraft's quasi-nonsingular elements, drift removed.

    Each spacecraft is averaged over ``periods[k]``, ITS OWN draconitic period, over which its
    short-period terms average out (one truth propagation of the pair serves both grids);
    :func:`scpformer.dynamics.mean_elements.average_qns` removes the secular drift.
    """
    grids = [np.arange(samples) * period / samples for period in periods]
    r_c, v_c = oe_to_eci(oe_c)
    r_d, v_d = oe_to_eci(oe_d)
    rtn0 = eci_to_rtn(r_c, v_c, r_d, v_d)
    res = propagate_relative(oe_c, rtn0, [0.0], t_out=np.concatenate(grids), j2=True)
    pairs = zip(grids, (res.oe_chief[:samples], res.oe_deputy[samples:]), strict=True)
    return [average_qns(oe_to_qns(oe), t) for t, oe in pairs]


def osculating_initial_state(
    instance: RendezvousInstance, iterations: int = 2, samples: int = 48
) -> tuple[np.ndarray, np.ndarray]:
    """Osculating target elements and relative RTN state at ``t_0`` (see
    :func:`_osculating_initial_state`); a pure function of the instance, so the last few
    results are kept: solving, verifying and saving one instance propagate the pair once."""
    oe_c, rtn0 = _osculating_initial_state(instance, iterations, samples)
    return oe_c.copy(), rtn0.copy()


@functools.lru_cache(maxsize=16)
def _osculating_initial_state(
    instance: RendezvousInstance, iterations: int, samples: int
) -> tuple[np.ndarray, np.ndarray]:
    """Osculating target elements and relative RTN state at ``t_0`` consistent with the model.

    The model's target elements and ``x_0`` are MEAN. Feeding them to the nonlinear propagator
    as osculating values offsets the relative semi-major axis by its short-period J2 term
    (~0.2 m at 100 m separation), which drifts into metres of along-track error per orbit. This
    fixed point removes the offset numerically: propagate each spacecraft over ITS OWN
    draconitic period with the truth model, average its quasi-nonsingular elements (angles with
    its first-order secular J2 drift removed), and shift the osculating elements by
    ``mean target - average``. Each spacecraft is averaged over its own period because its
    short-period terms are periodic in its own argument of latitude: averaging the servicer
    over the target's period instead biases its mean ROE by metres at ``a da`` of kilometres
    (+6.9 m in ``a da`` at -5.1 km). Two iterations agree with an independent averaging to
    ~2 mm in ``a dlambda`` and ~1 cm in ``a de`` at ``a da`` up to 5 km (tested), ~15 ms.
    Without J2 (``scenario.j2 = False``) mean and osculating coincide and nothing is done.

    Returns
    -------
    oe_target, rtn0
        Osculating classical elements of the target (6,) and the servicer's RTN state (6,).
    """
    oe_c = instance.target.oe.to_array()
    oe_d = roe_to_oe(oe_c, instance.roe0 / oe_c[0])
    if instance.scenario.j2:
        targets = [oe_to_qns(oe_c), oe_to_qns(oe_d)]
        periods = [2.0 * math.pi / (r[1] + r[2]) for r in map(j2_secular_rates, (oe_c, oe_d))]
        guess = [q.copy() for q in targets]
        for _ in range(iterations):
            osc = [qns_to_oe(q) for q in guess]
            means = _orbit_averaged_qns(osc[0], osc[1], periods, samples)
            for q, target, mean in zip(guess, targets, means, strict=True):
                delta = target - mean
                delta[[1, 5]] = wrap_to_pi(delta[[1, 5]])
                q += delta
        oe_c, oe_d = qns_to_oe(guess[0]), qns_to_oe(guess[1])
    r_c, v_c = oe_to_eci(oe_c)
    r_d, v_d = oe_to_eci(oe_d)
    return oe_c, eci_to_rtn(r_c, v_c, r_d, v_d)


def replay(
    instance: RendezvousInstance,
    dv: np.ndarray,
    tol: VerificationTolerances | None = None,
) -> TruthResult:
    """Propagate the impulses through the nonlinear two-body (+ J2) model.

    Returns ``samples_per_interval`` outputs per interval plus the final one; node ``k`` is
    output ``k * samples_per_interval`` (pre-impulse state, exactly at ``t_k``).
    """
    tol = tol or VerificationTolerances()
    t = instance.times()
    m = tol.samples_per_interval
    frac = np.arange(m) / m
    t_out = np.append((t[:-1, None] + np.diff(t)[:, None] * frac[None, :]).ravel(), t[-1])
    if tol.consistent_initial_state:
        oe_c, rtn0 = osculating_initial_state(instance)
    else:
        oe_c, rtn0 = instance.target.oe.to_array(), instance.rtn0_linear
    dv = np.asarray(dv, dtype=float)
    kicks = np.where(np.linalg.norm(dv, axis=1, keepdims=True) < tol.dv_zero_m_s, 0.0, dv)
    return propagate_relative(oe_c, rtn0, t[:-1], kicks, t_out=t_out, j2=instance.scenario.j2)


def _checks(kind: str) -> tuple[str, ...]:
    base = ("terminal_position_m", "terminal_velocity_m_s", "model_residual_m")
    approach = ("waypoint_position_m", "waypoint_velocity_m_s", "cone_m")
    return base + (approach if kind != "tpbvp" else ()) + (("keep_out",) if kind == "scp" else ())


def verify_solution(
    instance: RendezvousInstance,
    model: LinearModel,
    x: np.ndarray,
    dv: np.ndarray,
    kind: str,
    tol: VerificationTolerances | None = None,
) -> Verification:
    """Replay ``dv`` through the nonlinear propagator and check the constraints of ``kind``.

    ``terminal_error``: miss at ``t_N`` w.r.t. the docking port, as norms and per RTN
    component. ``max_defect``: largest position gap [m] between the linear prediction
    ``Psi_k x_k`` and the replay at the nodes (the model error, see the module docstring).
    ``node_violations``: keep-out (``1 - |E_koz dr|``), cone [m] and waypoint misses of the
    replay at the nodes, and the residual of the linear dynamics [m] (which catches an
    inaccurate conic solution). ``path_violations``: keep-out and cone between the nodes.
    Pass/fail uses the constraints of ``kind`` only (Problem 1 has no waypoint, cone or KOZ).
    """
    tol = tol or VerificationTolerances()
    sc = instance.scenario
    m, kw, n = tol.samples_per_interval, sc.n_waypoint, sc.n_nodes
    try:
        truth = replay(instance, dv, tol)
    except (ArithmeticError, RuntimeError, ValueError) as err:  # e.g. an escaping orbit
        return Verification(False, {}, math.inf, {}, {}, f"replay failed: {err}")
    nodes, dense = truth.rtn[::m], truth.rtn
    gap = nodes - model.rtn(x)
    miss = nodes[n] - np.r_[sc.dock_port_m, 0.0, 0.0, 0.0]
    wp_miss = nodes[kw] - np.r_[sc.waypoint_m, 0.0, 0.0, 0.0]
    terminal = {
        "position_m": float(np.linalg.norm(miss[:3])),
        "velocity_m_s": float(np.linalg.norm(miss[3:])),
    }
    terminal.update({f"{c}_m": float(v) for c, v in zip("rtn", miss[:3], strict=True)})
    terminal.update({f"v{c}_m_s": float(v) for c, v in zip("rtn", miss[3:], strict=True)})
    node = {
        "keep_out": _worst(-keep_out_slack(nodes[: kw + 1], sc)),
        "cone_m": _worst(-cone_slack(nodes[kw:n], sc)),
        "waypoint_position_m": float(np.linalg.norm(wp_miss[:3])),
        "waypoint_velocity_m_s": float(np.linalg.norm(wp_miss[3:])),
        "model_residual_m": max(model.residual(x, dv), float(np.abs(x[0] - instance.roe0).max())),
    }
    path = {
        "keep_out": _worst(-keep_out_slack(dense[: kw * m + 1], sc)),
        "cone_m": _worst(-cone_slack(dense[kw * m : n * m], sc)),
    }
    measured = {
        **node,
        "terminal_position_m": terminal["position_m"],
        "terminal_velocity_m_s": terminal["velocity_m_s"],
    }
    problems = [
        f"{name} {measured[name]:.3g} > {getattr(tol, name):.3g}"
        for name in _checks(kind)
        if measured[name] > getattr(tol, name)
    ]
    gap_v = float(np.linalg.norm(gap[:, 3:], axis=1).max())
    note = f"max linear-vs-truth gap {np.linalg.norm(gap[:, :3], axis=1).max():.3g} m, "
    note += f"{gap_v * 1e3:.3g} mm/s"
    return Verification(
        passed=not problems,
        terminal_error=terminal,
        max_defect=float(np.linalg.norm(gap[:, :3], axis=1).max()),
        node_violations=node,
        path_violations=path,
        message="; ".join([*problems, note]),
    )


def _worst(violation: np.ndarray) -> float:
    """Largest violation, clipped at zero (0 when every row holds)."""
    return float(max(0.0, violation.max())) if violation.size else 0.0


# ======================================================================================
# solving
# ======================================================================================
@dataclass(frozen=True)
class SCPState:
    """Iterate of the SCP of Section 4 (explicit; the algorithm itself holds no state)."""

    k: int  # iteration about to run, 1-based
    zeta: float  # trust region radius zeta_k [m] (Eq. 17-18)
    x_ref: np.ndarray  # reference trajectory de_bar_k (N+1, 6) [m]
    J_prev: float  # J_{k-1} [m/s] (the warm start's cost, or inf when it has none)


@dataclass(frozen=True)
class _Setup:
    instance: RendezvousInstance
    config: RendezvousSolverConfig
    model: LinearModel
    bounds: BoundaryData
    time: float  # s spent building the model and boundary data


def _setup(instance: RendezvousInstance, config: RendezvousSolverConfig) -> _Setup:
    start = time.perf_counter()
    model = linear_model(instance)
    bounds = boundary_data(instance, model)
    return _Setup(instance, config, model, bounds, time.perf_counter() - start)


def _subproblem(setup: _Setup, kind: str) -> RendezvousSubproblem:
    """The compiled subproblem of ``kind`` with this instance's dynamics and boundary data."""
    sc = setup.instance.scenario
    sub = compiled_subproblem(kind, sc.n_nodes, sc.n_waypoint, setup.config.scp.solver)
    b, model = setup.bounds, setup.model
    sub.set_dynamics(model.Phi, model.Phi @ model.B, b.x_init, b.x_dock)
    if kind != "tpbvp":
        sub.set_final_approach(b.x_wp, b.cone_A, b.cone_c, b.cone_b, b.cone_d)
    return sub


def _record(
    setup: _Setup,
    k: int,
    sol: SubproblemSolution,
    zeta: float,
    step: float,
    t_disc: float,
    t_total: float,
) -> IterationRecord:
    ok = sol.ok
    rtn = setup.model.rtn(sol.x) if ok else None
    sc = setup.instance.scenario
    return IterationRecord(
        iteration=k,
        accepted=ok,
        cost=sol.cost,
        penalty=_koz_penalty(rtn, sc) if ok else math.nan,
        J=sol.cost,
        L=sol.cost,
        rho=math.nan,
        trust_radius=zeta,
        virtual_control_norm=0.0,
        step_norm=step,
        tight_flags=tight_flags(rtn, sc, setup.config.tight_tol)
        if ok
        else np.zeros(len(constraint_index(sc)), dtype=bool),
        time_discretization=t_disc,
        time_solver=sol.solver_time,
        time_total=t_total,
        solver_status=sol.status,
    )


def _koz_penalty(rtn: np.ndarray, sc: RendezvousScenario) -> float:
    """Sum of keep-out violations ``max(0, 1 - |E_koz dr_k|)`` of the model trajectory."""
    return float(np.maximum(-keep_out_slack(rtn[: sc.n_waypoint + 1], sc), 0.0).sum())


def _convex(setup: _Setup, kind: str) -> tuple[SubproblemSolution, IterationRecord]:
    start = time.perf_counter()
    sub = _subproblem(setup, kind)
    sol = sub.solve(setup.config.scp.solver)
    return sol, _record(setup, 1, sol, math.inf, math.nan, 0.0, time.perf_counter() - start)


def _failure_status(kind: str, status: str) -> Status:
    """A certified infeasible convex problem means the instance is infeasible."""
    infeasible = status.startswith("infeasible")
    return Status.INFEASIBLE_INSTANCE if infeasible and kind != "scp" else Status.SOLVER_FAILED


def _scp_stop(scp: SCPParameters, state: SCPState, J: float, step: float) -> bool:
    """Convergence clause of Eq. 19, ``(zeta_k <= zeta_K) and (J_{k-1} - J_k < J_tol)``.

    With ``stop_test = "step"`` the realized step replaces ``zeta_k`` (see SCPParameters).
    """
    settled = (step if scp.stop_test == "step" else state.zeta) <= scp.zeta_K
    return settled and state.J_prev - J < scp.J_tol


def run_scp(
    setup: _Setup, x_warm: np.ndarray, J_warm: float
) -> tuple[Status, SubproblemSolution | None, list[IterationRecord], str]:
    """The SCP of Section 4 from the reference ``x_warm`` (N+1, 6) [m].

    Each iteration linearizes the keep-out constraint at the reference (Eqs. 15-16), solves the
    subproblem with trust radius ``zeta_k`` (Eq. 17), takes its solution as the next reference
    and shrinks ``zeta_{k+1} = beta zeta_k`` (Eq. 18), until Eq. 19. Every solved iterate
    satisfies Problem 3 in the linear model (the cut is conservative), so the cheapest one is
    returned, as in the ART reference code. ``optimal_inaccurate`` solves are accepted and
    listed in the message; verification then checks their linear-dynamics residual.
    """
    scp, sc = setup.config.scp, setup.instance.scenario
    kw = sc.n_waypoint
    sub = _subproblem(setup, "scp")
    x_warm = np.array(x_warm, dtype=float)
    x_warm[0] = setup.bounds.x_init  # node 0 is fixed; the trust region holds trivially there
    state = SCPState(k=1, zeta=scp.zeta_1, x_ref=x_warm, J_prev=J_warm)
    history: list[IterationRecord] = []
    best: SubproblemSolution | None = None
    inaccurate: list[int] = []
    while True:
        start = time.perf_counter()
        a, b = keep_out_cut(setup.model.Psi[: kw + 1], sc, state.x_ref[: kw + 1])
        sub.set_keep_out(a, b, state.x_ref[: kw + 1], state.zeta)
        t_disc = time.perf_counter() - start
        sol = sub.solve(scp.solver)
        step = float(np.linalg.norm(sol.x - state.x_ref, axis=1).max()) if sol.ok else math.nan
        history.append(
            _record(setup, state.k, sol, state.zeta, step, t_disc, time.perf_counter() - start)
        )
        if not sol.ok:
            kept = f"; returning the best of {state.k - 1} solved iterates" if best else ""
            return Status.SOLVER_FAILED, best, history, f"subproblem {state.k}: {sol.status}{kept}"
        if sol.status == INACCURATE:
            inaccurate.append(state.k)
        if best is None or sol.cost < best.cost:
            best = sol
        note = f"; accepted optimal_inaccurate at iterations {inaccurate}" if inaccurate else ""
        if _scp_stop(scp, state, sol.cost, step):
            return Status.CONVERGED, best, history, f"Eq. 19 met at iteration {state.k}{note}"
        if state.k >= scp.K:
            return Status.MAX_ITERATIONS, best, history, f"K = {scp.K} reached{note}"
        state = SCPState(state.k + 1, scp.beta * state.zeta, sol.x, sol.cost)


def _warm_start(
    setup: _Setup, warmstart: Any
) -> tuple[np.ndarray | None, float, Solution | None, Any]:
    """Reference states, their cost, the solve behind them and the warm start's record.

    ``warmstart`` is a provider (:mod:`scpformer.warmstart`), a precomputed
    ``WarmStartResult``, a name of :data:`WARMSTARTS` (the convex provider of Problem 1 or
    2), a Solution, a Trajectory or an (N+1, 6) array (a fixed guess).
    """
    from scpformer.warmstart.base import as_provider
    from scpformer.warmstart.convex import RendezvousConvexWarmStart

    n = setup.instance.n_nodes
    named = {kind: partial(RendezvousConvexWarmStart, kind, setup.config) for kind in WARMSTARTS}
    result = as_provider(warmstart, named).guess(setup.instance)
    if result.trajectory is None:
        return None, math.nan, result.solution, result.record
    x = np.asarray(result.trajectory.x, dtype=float)
    u = np.asarray(result.trajectory.u, dtype=float)
    J = result.record.cost if u.shape == (n, 3) and math.isfinite(result.record.cost) else math.inf
    if x.shape != (n + 1, 6):
        raise ValueError(f"warmstart states must have shape ({n + 1}, 6), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(
            f"the {result.record.source} warm start produced non-finite states (nan or inf at "
            f"{int(np.sum(~np.isfinite(x).all(axis=1)))} of {n + 1} nodes): check its inputs "
            "(for ART: --rtg, --ctg) and its model"
        )
    return x, J, result.solution, result.record


def _finish(
    setup: _Setup,
    kind: str,
    status: Status,
    sol: SubproblemSolution | None,
    history: list[IterationRecord],
    message: str,
    start: float,
    verify: bool,
    extra_solver: float = 0.0,
) -> Solution:
    verification, t_ver = None, 0.0
    if sol is not None and sol.ok and verify:
        t0 = time.perf_counter()
        verification = verify_solution(
            setup.instance, setup.model, sol.x, sol.u, kind, setup.config.verification
        )
        t_ver = time.perf_counter() - t0
        status, message = verified_status(status, message, verification)
    ok = sol is not None and sol.ok
    timing = Timing(
        total=time.perf_counter() - start,
        discretization=setup.time + sum(r.time_discretization for r in history),
        solver=extra_solver + sum(r.time_solver for r in history),
        verification=t_ver,
    )
    return Solution(
        status=status,
        trajectory=Trajectory(x=sol.x, u=sol.u, p=np.zeros(0)) if ok else None,
        t=setup.model.t,
        cost=sol.cost if ok else math.nan,
        iterations=len(history),
        history=history,
        verification=verification,
        timing=timing,
        message=message,
    )


def _solve_convex(setup: _Setup, kind: str, verify: bool, start: float) -> Solution:
    sol, record = _convex(setup, kind)
    label = f"Problem {PROBLEMS.index(kind) + 1} ({kind}): {sol.status}"
    if sol.ok:
        flag = " (accepted optimal_inaccurate)" if sol.status == INACCURATE else ""
        status, message = Status.CONVERGED, label + flag
    else:
        status, message = _failure_status(kind, sol.status), label
    return _finish(setup, kind, status, sol, [record], message, start, verify)


def solve(
    instance: RendezvousInstance,
    problem: ProblemKind = "scp",
    warmstart: Any = "convex",
    config: RendezvousSolverConfig | None = None,
    *,
    verify: bool = True,
) -> Solution:
    """Solve Problem 1 (``"tpbvp"``), 2 (``"convex"``) or 3 (``"scp"``) of the ART paper.

    Parameters
    ----------
    instance
        The rendezvous instance.
    problem
        Which OCP to solve.
    warmstart
        Problem 3 only: the initial reference, ``"tpbvp"`` or ``"convex"`` (solved here), a
        warm start provider (:mod:`scpformer.warmstart`, e.g. ``ArtWarmStart``) or its
        precomputed ``WarmStartResult``, a :class:`~scpformer.scp.solution.Solution` (e.g. of
        Problem 2, to time the SCP alone), a :class:`~scpformer.scp.solution.Trajectory` or
        ROE states (N+1, 6) [m]. ``J_0`` of Eq. 19 is the warm start's cost when it carries
        impulses. The guess only starts the SCP; it is never returned as the solution.
    config
        SCP constants, conic solver and verification tolerances (default: Table 1).
    verify
        Replay the impulses through the nonlinear propagator (:func:`verify_solution`).

    Returns
    -------
    Solution
        ``trajectory.x`` (N+1, 6) ROE [m], ``trajectory.u`` (N, 3) impulses [m/s],
        ``trajectory.p`` empty; ``t`` (N+1,) [s]; ``cost`` = ``sum |dv|_2`` [m/s];
        Problem 3: ``extras["warmstart"]``, the warm start's record (``WarmStartRecord.to_dict``:
        source, time, cost, constraint-to-go, acceptance and fallback). A failing
        conic solve is a status (``INFEASIBLE_INSTANCE`` for a certified infeasible convex
        problem, else ``SOLVER_FAILED``), never an exception.
    """
    if problem not in PROBLEMS:
        raise ValueError(f"problem must be one of {PROBLEMS}, got {problem!r}")
    if not isinstance(instance, RendezvousInstance):
        raise ValueError(f"instance must be a RendezvousInstance, got {type(instance).__name__}")
    config = RendezvousSolverConfig() if config is None else config
    check_type("config", config, RendezvousSolverConfig)
    start = time.perf_counter()
    setup = _setup(instance, config)
    if problem != "scp":
        return _solve_convex(setup, problem, verify, start)
    x_warm, J_warm, warm, record = _warm_start(setup, warmstart)
    timed_warm = warm is not None and warm.timing is not None and isinstance(warmstart, str)
    warm_solver = warm.timing.solver if timed_warm else 0.0
    if x_warm is None:
        infeasible = warm is not None and warm.status is Status.INFEASIBLE_INSTANCE
        status = Status.INFEASIBLE_INSTANCE if infeasible else Status.SOLVER_FAILED
        message = f"warm start failed: {warm.message if warm is not None else record.reason}"
        solution = _finish(setup, "scp", status, None, [], message, start, verify, warm_solver)
    else:
        status, best, history, message = run_scp(setup, x_warm, J_warm)
        solution = _finish(setup, "scp", status, best, history, message, start, verify,
                           warm_solver)  # fmt: skip
    return replace(solution, extras={**solution.extras, "warmstart": record.to_dict()})
