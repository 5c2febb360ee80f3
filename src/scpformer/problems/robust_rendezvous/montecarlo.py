"""Monte Carlo verification of passive safety under navigation, actuation and process errors.

For each node ``i`` of a solved trajectory and each of ``n_samples`` draws:

1. the true state right before the maneuver is the nominal one plus a navigation error
   ``~ N(0, X_nav(x_i))`` and a process-noise error ``~ N(0, Q)`` (Eqs. 10-11, Table 2, in
   scaled ROE, mapped to RTN with ``Psi(t_i)`` for the nonlinear propagator);
2. the maneuver ``u_i`` is executed with a Gates error drawn in its burn frame (Eq. 12,
   :meth:`GatesModel.sample`);
3. control is lost: the state drifts for ``T_safety`` and every entry into the node's active
   safety ellipsoid (AE before ``n_ae_to_koz``, KOZ after) is counted.

The empirical violation probability per node is reported next to the design level ``Delta``,
both at the ``N_safety`` instants the constraint is designed on (``p_design``) and on a dense
grid of the arc (``p_dense``; the design only checks ``N_safety`` instants, so this one may
exceed ``Delta`` where the arc dips between two samples).

Propagators
-----------
* ``"linear"``: the design model itself (mean-ROE STM and ``Psi``): checks the chance
  constraint's transcription (Eqs. 14-16) exactly as designed.
* ``"truth"``: two-body + J2 in ECI, chief and deputies integrated together Encke-style (the
  deputy offset is the state, the relative acceleration the exact difference ``a(r_c + rho) -
  a(r_c)``), the same force model as :func:`scpformer.dynamics.truth.propagate_relative` but
  with a fixed-step RK4 vectorized over nodes and samples (``dt ~ 20 s``; agreement with the
  adaptive DOP853 propagator is tested to centimetres over an orbit). The nominal states at the
  nodes are the nonlinear replay of the plan from the consistent osculating initial state; the
  errors of step 1 are mapped to RTN with ``Psi`` (first order, they are metres to tens of
  metres).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from scpformer.dynamics.orbits import J2 as J2_EARTH
from scpformer.dynamics.orbits import (
    accel_two_body_j2,
    eci_to_rtn,
    propagate_kepler,
    propagate_mean_j2,
    rtn_dcm,
    rtn_to_eci,
)
from scpformer.dynamics.roe import psi_matrix, stm_j2, stm_kepler
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.problem import replay
from scpformer.problems.robust_rendezvous.safety import drift_geometry, linear_model
from scpformer.validation import check_positive

PROPAGATORS = ("linear", "truth")
_CHUNK_FLOATS = 20_000_000  # largest (nodes, samples, instants, 6) block held at once


@dataclass(frozen=True, kw_only=True)
class MonteCarloConfig:
    """How the Monte Carlo check samples and propagates (not in the paper)."""

    n_samples: int = 1000  # draws per node
    propagator: str = "truth"  # "truth" (two-body + J2, RK4) or "linear" (design model)
    rk4_step_s: float = 20.0  # largest RK4 step of the truth propagator [s]
    dense_per_sample: int = 8  # dense-grid points per interval between design instants
    seed: int = 0  # seed of the numpy Generator

    def __post_init__(self) -> None:
        for name in ("n_samples", "dense_per_sample", "seed"):
            value = getattr(self, name)
            low = 0 if name == "seed" else 1
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise ValueError(f"monte_carlo.{name} must be an integer >= {low}, got {value!r}")
        if self.propagator not in PROPAGATORS:
            raise ValueError(
                f"monte_carlo.propagator must be one of {PROPAGATORS}, got {self.propagator!r}"
            )
        check_positive("monte_carlo.rk4_step_s", self.rk4_step_s)


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
    m = cfg.dense_per_sample
    dense = np.linspace(0.0, design[-1], (design.size - 1) * m + 1)
    return dense, m


def _errors(
    instance: RobustInstance, x: np.ndarray, u: np.ndarray, nodes: np.ndarray,
    rng: np.random.Generator, n: int,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """ROE errors (nav + process) (K, M, 6) [m] and executed impulses (K, M, 3) [m/s]."""
    unc, model = instance.uncertainty, linear_model(instance)
    rho = np.linalg.norm(np.einsum("kij,kj->ki", model.Psi[nodes, :3, :], x[nodes]), axis=1)
    sigma_nav = rho[:, None] * unc.navigation.scale(rho)  # (K, 6)
    nav = rng.standard_normal((nodes.size, n, 6)) * sigma_nav[:, None, :]
    chol = np.linalg.cholesky(unc.process_noise.matrix)
    proc = rng.standard_normal((nodes.size, n, 6)) @ chol.T
    du = np.swapaxes(unc.actuation.sample(u[nodes], rng, n), 0, 1)  # (K, M, 3)
    return nav + proc, u[nodes][:, None, :] + du


def _linear_min_distance(
    instance: RobustInstance, x: np.ndarray, nodes: np.ndarray, e: np.ndarray, u_exec: np.ndarray,
    tau: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Normalized distances (K, M, T) of the drift samples in the design (linear) model."""
    model = linear_model(instance)
    sc = instance.scenario
    oe0 = instance.target.oe.to_array()
    propagate, stm = (propagate_mean_j2, stm_j2) if sc.j2 else (propagate_kepler, stm_kepler)
    t_nodes = model.t[nodes]
    y = x[nodes][:, None, :] + e + np.einsum("kij,kmj->kmi", model.B[nodes], u_exec)
    Phi = stm(propagate(oe0, t_nodes)[:, None, :], tau[None, :])  # (K, T, 6, 6)
    Psi = psi_matrix(propagate(oe0, t_nodes[:, None] + tau[None, :]))
    E = sc.ellipsoid_E()[nodes]
    G = np.einsum("krs,ktsj,ktjl->ktrl", E, Psi[..., :3, :], Phi)  # (K, T, 3, 6)
    return np.linalg.norm(np.einsum("ktrl,kml->kmtr", G, y), axis=-1)


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


def _truth_min_distance(
    instance: RobustInstance, u: np.ndarray, nodes: np.ndarray, e: np.ndarray,
    u_exec: np.ndarray, tau: np.ndarray, cfg: MonteCarloConfig,
) -> np.ndarray:  # fmt: skip
    """Normalized distances (K, M, T) along drift arcs in the two-body + J2 model."""
    model = linear_model(instance)
    truth = replay(instance, u)
    chief = truth.x_chief[nodes]  # (K, 6) pre-impulse ECI at t_i
    rtn = truth.rtn[nodes][:, None, :] + np.einsum("kij,kmj->kmi", model.Psi[nodes], e)
    r_d, v_d = rtn_to_eci(chief[:, None, :3], chief[:, None, 3:], rtn)
    C = rtn_dcm(r_d, v_d)  # deputy RTN frame, where the impulse is expressed
    v_d = v_d + np.einsum("kmji,kmj->kmi", C, u_exec)
    states = propagate_drift_truth(chief, np.concatenate([r_d, v_d], -1), tau, cfg.rk4_step_s,
                                   instance.scenario.j2)  # fmt: skip
    E = instance.scenario.ellipsoid_E()[nodes]
    return np.linalg.norm(np.einsum("krs,kmts->kmtr", E, states[..., :3]), axis=-1)


def monte_carlo(
    instance: RobustInstance,
    x: np.ndarray,
    u: np.ndarray,
    config: MonteCarloConfig | None = None,
    nodes: np.ndarray | None = None,
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
    chunk = max(1, _CHUNK_FLOATS // (cfg.n_samples * tau.size * 6))
    p_design, p_dense, d_min = [], [], []
    for lo in range(0, nodes.size, chunk):  # bounded memory: (chunk, M, T, 6) at a time
        sel = slice(lo, lo + chunk)
        if cfg.propagator == "linear":
            d = _linear_min_distance(instance, x, nodes[sel], e[sel], u_exec[sel], tau)
        else:
            d = _truth_min_distance(instance, u, nodes[sel], e[sel], u_exec[sel], tau, cfg)
        inside = d < 1.0  # (K, M, T)
        p_design.append(inside[:, :, ::m].any(axis=2).mean(axis=1))
        p_dense.append(inside.any(axis=2).mean(axis=1))
        d_min.append(d.min(axis=2))
    return MonteCarloResult(
        nodes=nodes,
        p_design=np.concatenate(p_design),
        p_dense=np.concatenate(p_dense),
        min_distance=np.concatenate(d_min),
        n_samples=cfg.n_samples,
        delta=instance.uncertainty.delta,
        propagator=cfg.propagator,
        wall_s=time.perf_counter() - start,
    )
