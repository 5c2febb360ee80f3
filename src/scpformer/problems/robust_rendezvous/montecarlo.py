"""Monte Carlo verification of passive safety under navigation, actuation and process errors.

For each node ``i`` of a solved trajectory and each of ``n_samples`` draws:

1. the true state right before the maneuver is the nominal one plus a navigation error
   ``~ N(0, X_nav(x_i))`` and a process-noise error ``~ N(0, Q)`` (Eqs. 10-11, Table 2, in
   scaled ROE, mapped to RTN with ``Psi(t_i)`` for the nonlinear propagator); with
   navigation fixes only every ``fix_every`` nodes (``UncertaintyModel.fix_every``), the
   error between the fixes is the previous node's, after its maneuver, carried by the STM
   plus the node's process noise (the plan is flown open loop in between);
2. the maneuver ``u_i`` is executed with a Gates error drawn in its burn frame (Eq. 12,
   :meth:`GatesModel.sample`);
3. control is lost: the state drifts for ``T_safety`` and every entry into the node's active
   safety ellipsoid (AE before ``n_ae_to_koz``, KOZ after) is counted.

The empirical violation probability per node is reported next to the design level ``Delta``,
both at the ``N_safety`` design instants (``p_design``) and on a dense grid of the arc, every
``dense_step_s`` (5 s) including the design instants (``p_dense``). The constraint is imposed
at each arc's worst instant in continuous time (:mod:`.safety`), so ``p_dense`` is the one
to hold against ``Delta``.

Propagators
-----------
* ``"linear"``: the design model linearized about the plan (the drift Jacobian of the plan's
  dynamics, mean ROE, and ``Psi``): checks the chance constraint's transcription (Eqs.
  14-16) as designed.
* ``"truth"``: two-body + J2 in ECI, chief and deputies integrated together Encke-style (the
  deputy offset is the state, the relative acceleration the exact difference ``a(r_c + rho) -
  a(r_c)``), the same force model as :func:`scpformer.dynamics.truth.propagate_relative` but
  with a fixed-step RK4 vectorized over nodes and samples (``dt ~ 20 s``; agreement with the
  adaptive DOP853 propagator is tested to centimetres over an orbit) and cubic Hermite
  interpolation of the RTN state to the dense grid (error ~1e-5 m at 20 s steps). The nominal
  states at the nodes are the nonlinear replay of the plan from the consistent osculating
  initial state; the errors of step 1 are mapped to RTN with ``Psi`` (first order, they are
  metres to tens of metres).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from dataclasses import dataclass

import numpy as np

from scpformer.dynamics.orbits import J2 as J2_EARTH
from scpformer.dynamics.orbits import (
    accel_two_body_j2,
    eci_to_rtn,
    rtn_dcm,
    rtn_to_eci,
)
from scpformer.problems.rendezvous.linear_model import LinearModel
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.plan_dynamics import linearize_dynamics
from scpformer.problems.robust_rendezvous.problem import replay
from scpformer.problems.robust_rendezvous.safety import drift_geometry, linear_model
from scpformer.validation import check_int, check_positive

PROPAGATORS = ("linear", "truth")
_CHUNK_FLOATS = 20_000_000  # largest (nodes, samples, instants, 6) block held at once


MAX_SAMPLES = 200_000  # largest number of draws per node accepted (memory)


@dataclass(frozen=True, kw_only=True)
class MonteCarloConfig:
    """How the Monte Carlo check samples and propagates (not in the paper)."""

    n_samples: int = 1000  # draws per node
    propagator: str = "truth"  # "truth" (two-body + J2, RK4) or "linear" (design model)
    rk4_step_s: float = 20.0  # largest RK4 step of the truth propagator [s]
    dense_step_s: float = 5.0  # largest spacing of the dense grid of each drift arc [s]
    seed: int = 0  # seed of the numpy Generator

    def __post_init__(self) -> None:
        # memory, not statistics: the (nodes x draws) table of smallest distances holds 8 bytes
        # per entry, 160 MB at N = 100 nodes and the largest count; 1e12 draws would need 800 TB
        check_int("monte_carlo.n_samples", self.n_samples, least=1, most=MAX_SAMPLES)
        check_int("monte_carlo.seed", self.seed, least=0)
        if self.propagator not in PROPAGATORS:
            raise ValueError(
                f"monte_carlo.propagator must be one of {PROPAGATORS}, got {self.propagator!r}"
            )
        check_positive("monte_carlo.rk4_step_s", self.rk4_step_s)
        check_positive("monte_carlo.dense_step_s", self.dense_step_s)


@dataclass(frozen=True)
class MonteCarloResult:
    """Empirical violation probabilities per node (nodes ``0 .. N-1`` unless selected)."""

    nodes: np.ndarray  # (K,) node indices checked
    p_design: np.ndarray  # (K,) fraction of draws inside the ellipsoid at a design instant
    p_dense: np.ndarray  # (K,) same on the dense grid of the arc
    min_distance: np.ndarray  # (K, M) smallest normalized distance |E dr| of each draw (dense)
    n_samples: int
    delta: float  # design level Delta
    propagator: str
    wall_s: float

    def passes(self, confidence: float = 1e-4, dense: bool = False) -> bool:
        """No node's count exceeds the ``1 - confidence`` binomial quantile at ``Delta``."""
        return bool(np.all(self.counts(dense) <= self.threshold(confidence)))

    def counts(self, dense: bool = False) -> np.ndarray:
        """Violating draws per node."""
        p = self.p_dense if dense else self.p_design
        return np.rint(p * self.n_samples).astype(int)

    def threshold(self, confidence: float = 1e-4) -> int:
        """Largest count compatible with ``Delta`` at the given one-sided confidence."""
        from scipy.stats import binom

        return int(binom.isf(confidence, self.n_samples, self.delta))


def _grid(instance: RobustInstance, cfg: MonteCarloConfig) -> tuple[np.ndarray, int]:
    """Dense drift offsets (including the design instants every ``m`` points) and ``m``."""
    design = drift_geometry(instance).tau
    if design.size == 1:
        return design, 1
    m = max(1, math.ceil((design[1] - design[0]) / cfg.dense_step_s))
    dense = np.linspace(0.0, design[-1], (design.size - 1) * m + 1)
    return dense, m


def _errors(
    instance: RobustInstance, x: np.ndarray, u: np.ndarray, nodes: np.ndarray,
    rng: np.random.Generator, n: int,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """ROE errors (nav + process) (K, M, 6) [m] and executed impulses (K, M, 3) [m/s].

    With navigation fixes every ``K = fix_every > 1`` nodes, the errors are drawn for every
    node and chained between the fixes (:func:`_carry_errors`), then the ``nodes`` taken."""
    unc, model = instance.uncertainty, linear_model(instance)
    drawn = nodes if unc.fix_every == 1 else np.arange(u.shape[0])
    rho = np.linalg.norm(np.einsum("kij,kj->ki", model.Psi[drawn, :3, :], x[drawn]), axis=1)
    sigma_nav = rho[:, None] * unc.navigation.scale(rho)  # (K, 6)
    nav = rng.standard_normal((drawn.size, n, 6)) * sigma_nav[:, None, :]
    chol = np.linalg.cholesky(unc.process_noise.matrix)
    proc = rng.standard_normal((drawn.size, n, 6)) @ chol.T
    du = np.swapaxes(unc.actuation.sample(u[drawn], rng, n), 0, 1)  # (K, M, 3)
    e = nav + proc
    if unc.fix_every > 1:
        e = _carry_errors(e, proc, du, model, unc.fixes(u.shape[0]))[nodes]
        du = du[nodes]
    return e, u[nodes][:, None, :] + du


def _carry_errors(
    e: np.ndarray, proc: np.ndarray, du: np.ndarray, model: LinearModel, fixes: np.ndarray
) -> np.ndarray:
    """Pre-maneuver errors of a plan flown open loop between navigation fixes, (N, M, 6) [m].

    At a fix the error is the drawn navigation + process error ``e_i``; at a node without
    one it is the previous node's error after its maneuver, carried by the STM, plus the
    node's process noise: ``Phi_{i-1} (e_{i-1} + B_{i-1} du_{i-1}) + w_i`` (first order, as
    the covariance of :func:`scpformer.dynamics.uncertainty.covariance_history`)."""
    out = e.copy()
    for i in np.flatnonzero(~fixes):
        post = out[i - 1] + du[i - 1] @ model.B[i - 1].T  # (M, 6)
        out[i] = post @ model.Phi[i - 1].T + proc[i]
    return out


def _linear_min_distance(
    instance: RobustInstance, x: np.ndarray, u: np.ndarray, nodes: np.ndarray, e: np.ndarray,
    u_exec: np.ndarray, tau: np.ndarray, dynamics: str,
) -> np.ndarray:  # fmt: skip
    """Normalized distances (K, M, T) of the drift in the design model about the plan: the
    plan's post-impulse state, plus the errors and the impulse error through ``B``, drifted
    with the plan's drift Jacobian (first order in the errors)."""
    model = linear_model(instance)
    dyn = linearize_dynamics(instance, model, x, u, dynamics)
    geometry = drift_geometry(instance, dynamics=dynamics)
    B = dyn.B[nodes]
    dy = e + np.einsum("kij,kmj->kmi", B, u_exec - u[nodes][:, None, :])  # (K, M, 6)
    sub = dataclasses.replace(geometry, t=geometry.t[nodes], E=geometry.E[nodes],
                              oe_nodes=geometry.oe_nodes[nodes],
                              qns_nodes=geometry.qns_nodes[nodes])  # fmt: skip
    x_t, jac, EDPsi = sub.drift(dyn.y[nodes], np.broadcast_to(tau, (nodes.size, tau.size)))
    states = x_t[:, None] + np.einsum("ktij,kmj->kmti", jac, dy)  # (K, M, T, 6)
    return np.linalg.norm(np.einsum("ktrl,kmtl->kmtr", EDPsi, states), axis=-1)


def _rk4_relative(
    chief: np.ndarray, rel: np.ndarray, h: float, j2: float
) -> tuple[np.ndarray, np.ndarray]:
    """One RK4 step of chief (K, 6) and Encke offsets (K, M, 6) in ECI."""

    def f(c: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        a_c = accel_two_body_j2(c[:, :3], j2=j2)
        a_d = accel_two_body_j2(c[:, None, :3] + d[..., :3], j2=j2) - a_c[:, None, :]
        return np.concatenate([c[:, 3:], a_c], -1), np.concatenate([d[..., 3:], a_d], -1)

    k1 = f(chief, rel)
    k2 = f(chief + 0.5 * h * k1[0], rel + 0.5 * h * k1[1])
    k3 = f(chief + 0.5 * h * k2[0], rel + 0.5 * h * k2[1])
    k4 = f(chief + h * k3[0], rel + h * k3[1])
    chief = chief + h / 6.0 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
    rel = rel + h / 6.0 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return chief, rel


def propagate_drift_truth(
    chief0: np.ndarray, deputy0: np.ndarray, tau: np.ndarray, max_step: float, j2: bool = True
) -> np.ndarray:
    """Relative RTN states (K, M, T, 6) of deputies drifting from ECI states at ``tau``.

    ``chief0`` (K, 6) and ``deputy0`` (K, M, 6) are ECI states at the start of each arc;
    ``tau`` (T,) evenly spaced offsets from 0 [s]. Fixed-step RK4 with at most ``max_step``.
    """
    j2_val = J2_EARTH if j2 else 0.0
    out = np.empty((*deputy0.shape[:2], tau.size, 6))
    chief, rel = chief0.copy(), deputy0 - chief0[:, None, :]
    out[:, :, 0] = eci_to_rtn(chief[:, None, :3], chief[:, None, 3:], deputy0[..., :3],
                              deputy0[..., 3:])  # fmt: skip
    for k in range(1, tau.size):
        span = tau[k] - tau[k - 1]
        steps = max(1, math.ceil(span / max_step))
        for _ in range(steps):
            chief, rel = _rk4_relative(chief, rel, span / steps, j2_val)
        r_d, v_d = chief[:, None, :3] + rel[..., :3], chief[:, None, 3:] + rel[..., 3:]
        out[:, :, k] = eci_to_rtn(chief[:, None, :3], chief[:, None, 3:], r_d, v_d)
    return out


def _hermite(p0, v0, p1, v1, h: float, theta: np.ndarray) -> np.ndarray:
    """Cubic Hermite interpolation (..., F, 3) of positions between two states at ``theta``
    ``(F,)`` in ``[0, 1]`` of a step of ``h`` seconds."""
    t2, t3 = theta**2, theta**3
    w = (2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + theta, -2 * t3 + 3 * t2, t3 - t2)
    out = w[0][:, None] * p0[..., None, :] + (h * w[1])[:, None] * v0[..., None, :]
    return out + w[2][:, None] * p1[..., None, :] + (h * w[3])[:, None] * v1[..., None, :]


def _truth_min_distance(
    instance: RobustInstance, u: np.ndarray, nodes: np.ndarray, e: np.ndarray,
    u_exec: np.ndarray, tau: np.ndarray, m: int, cfg: MonteCarloConfig,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Smallest normalized distances (K, M) along the drift arcs in the two-body + J2 model, at
    the design instants ``tau[::m]`` and on the whole grid ``tau``.

    RK4 steps of at most ``rk4_step_s`` between design instants; the RTN state is interpolated
    to the grid points inside each step (cubic Hermite, the RTN velocity being the derivative
    of the RTN position), so the grid costs no extra force evaluations.
    """
    model = linear_model(instance)
    truth = replay(instance, u)
    chief = truth.x_chief[nodes]  # (K, 6) pre-impulse ECI at t_i
    rtn = truth.rtn[nodes][:, None, :] + np.einsum("kij,kmj->kmi", model.Psi[nodes], e)
    r_d, v_d = rtn_to_eci(chief[:, None, :3], chief[:, None, 3:], rtn)
    C = rtn_dcm(r_d, v_d)  # deputy RTN frame, where the impulse is expressed
    v_d = v_d + np.einsum("kmji,kmj->kmi", C, u_exec)
    rel = np.concatenate([r_d, v_d], -1) - chief[:, None, :]
    E = instance.scenario.ellipsoid_E()[nodes]
    j2 = J2_EARTH if instance.scenario.j2 else 0.0

    def distance(pos: np.ndarray) -> np.ndarray:  # (K, M, ..., 3) -> (K, M, ...)
        return np.linalg.norm(np.einsum("krs,km...s->km...r", E, pos), axis=-1)

    def rtn_state(c: np.ndarray, d: np.ndarray) -> np.ndarray:
        r, v = c[:, None, :3] + d[..., :3], c[:, None, 3:] + d[..., 3:]
        return eci_to_rtn(c[:, None, :3], c[:, None, 3:], r, v)

    state = rtn_state(chief, rel)
    d_design = d_dense = distance(state[..., :3])
    for k in range(0, tau.size - 1, m):  # one design interval
        fine = tau[k : k + m + 1]
        steps = max(1, math.ceil((fine[-1] - fine[0]) / cfg.rk4_step_s))
        for c0, c1 in itertools.pairwise(np.linspace(fine[0], fine[-1], steps + 1)):
            chief, rel = _rk4_relative(chief, rel, c1 - c0, j2)
            nxt = rtn_state(chief, rel)
            inside = fine[(fine > c0) & (fine < c1)]
            if inside.size:
                pos = _hermite(state[..., :3], state[..., 3:], nxt[..., :3], nxt[..., 3:],
                               c1 - c0, (inside - c0) / (c1 - c0))  # fmt: skip
                d_dense = np.minimum(d_dense, distance(pos).min(axis=-1))
            state = nxt
        d_end = distance(state[..., :3])
        d_design, d_dense = np.minimum(d_design, d_end), np.minimum(d_dense, d_end)
    return d_design, d_dense


def monte_carlo(
    instance: RobustInstance,
    x: np.ndarray,
    u: np.ndarray,
    config: MonteCarloConfig | None = None,
    nodes: np.ndarray | None = None,
    dynamics: str = "nonlinear",
) -> MonteCarloResult:
    """Empirical probability of entering the active safety ellipsoid during each free drift.

    Parameters
    ----------
    instance
        Supplies the uncertainty models, ``Delta``, ``T_safety`` and the ellipsoids.
    x, u
        The plan: states (N+1, 6) [m] and impulses (N, 3) [m/s].
    config
        Samples, propagator, seed.
    nodes
        Node indices to check (default ``0 .. N-1``).
    dynamics
        The plan's model (``"nonlinear"`` or ``"stm"``, ``Solution.extras["dynamics"]``):
        gives the nominal post-impulse states and drift of the ``"linear"`` propagator.
    """
    cfg = config or MonteCarloConfig()
    start = time.perf_counter()
    n = instance.n_nodes
    nodes = np.arange(n) if nodes is None else np.asarray(nodes, dtype=int)
    if nodes.ndim != 1 or nodes.size == 0 or nodes.min() < 0 or nodes.max() >= n:
        raise ValueError(f"nodes must be a non-empty list of indices in [0, {n - 1}]")
    rng = np.random.default_rng(cfg.seed)
    e, u_exec = _errors(instance, x, u, nodes, rng, cfg.n_samples)
    tau, m = _grid(instance, cfg)
    per_node = cfg.n_samples * (tau.size * 6 if cfg.propagator == "linear" else 64)
    chunk = max(1, _CHUNK_FLOATS // per_node)
    d_design, d_dense = [], []
    for lo in range(0, nodes.size, chunk):  # bounded memory
        sel = slice(lo, lo + chunk)
        if cfg.propagator == "linear":
            d = _linear_min_distance(instance, x, u, nodes[sel], e[sel], u_exec[sel], tau,
                                     dynamics)  # fmt: skip
            d_design.append(d[:, :, ::m].min(axis=2))
            d_dense.append(d.min(axis=2))
        else:
            pair = _truth_min_distance(instance, u, nodes[sel], e[sel], u_exec[sel], tau, m, cfg)
            d_design.append(pair[0])
            d_dense.append(pair[1])
    design, dense = np.concatenate(d_design), np.concatenate(d_dense)
    return MonteCarloResult(
        nodes=nodes,
        p_design=(design < 1.0).mean(axis=1),
        p_dense=(dense < 1.0).mean(axis=1),
        min_distance=dense,
        n_samples=cfg.n_samples,
        delta=instance.uncertainty.delta,
        propagator=cfg.propagator,
        wall_s=time.perf_counter() - start,
    )
