"""Passive safety with a chance-constraint margin: Eqs. 2, 7, 14-16 of the robust ART paper.

Notation (nodes as in :mod:`.scenario`)
---------------------------------------
* ``y_i = x_i + B_i u_i`` [m]: scaled mean ROE right after the impulse at ``t_i``,
  ``i = 0 .. N-1``; ``X_i`` [m^2]: its covariance, Eq. 14 (navigation + Gates + process noise).
* Free drift from ``t_i``: ``tau_j = j T_safety / (N_safety - 1)``, ``j = 0 .. N_safety-1``
  (both ends included; one sample ``tau = 0`` when ``T_safety = 0``: collision avoidance).
* ``G_ij = E_i D Psi(t_i + tau_j) Phi(t_i + tau_j, t_i)`` (3, 6) [1/m]; the normalized
  distance of the drift sample from the target's safety ellipsoid is ``d_ij(y) = |G_ij y|_2``
  (``>= 1`` outside; ``E_i^2 = P`` of the AE or the KOZ, Sec. 4).
* ``t* = t_i + tau_{j*}``, ``j* = argmin_j d_ij(y_bar_i)``: minimum-separation instant (Eq. 16).

Constraint (Eqs. 2, 15-16), normalized. With ``M_i = G*^T G*`` Eq. 16 reads
``a_ps = M_i y_bar``, ``b_ps = sqrt(y_bar^T M_i y_bar) = d*`` and Eq. 15 is
``-a_ps^T y + b_ps + beta <= 0``. Dividing by ``b_ps > 0`` gives the same set with the unit
gradient ``a_hat = a_ps / b_ps = grad d*(y_bar)``:

    h_i(y) = 1 + beta_hat_i - a_hat_i^T y <= 0,      beta_hat_i = beta_i / b_ps
           = q(Delta) sqrt(a_hat_i^T X_i a_hat_i),

which is the first-order expansion at ``y_bar`` of the nonlinear
``h_i(y) = 1 + beta_hat_i(y) - min_j d_ij(y)`` (``d`` is 1-homogeneous, so
``d(y_bar) = a_hat^T y_bar``). The code evaluates and linearizes this normalized form
(dimensionless; its values are Eq. 15 divided by ``b_ps``), which keeps the virtual buffers of
all nodes on one scale whatever the range (``b_ps`` spans 1 to 20 here).

Margin. Eq. 16 prints ``beta = q |X(t*)^(1/2) a_ps|`` with ``a_ps`` the gradient with respect
to ``x(t_i)``; the variance of the linearized constraint is ``a_ps^T X(t_i) a_ps``, which equals
``g^T X(t*) g`` for the gradient ``g`` with respect to the state at ``t*`` and
``X(t*) = Phi X(t_i) Phi^T`` (Eq. 14). The code computes ``a_hat^T X_i a_hat`` (no propagation
needed); :func:`covariance_at_tstar` returns ``X(t*)`` for plots. The margin is held at the
reference while the subproblem is solved (the paper's Eq. 17 "given beta"); the nonlinear
``h`` recomputes it at each candidate.

State at the contingency. Eq. 16 writes ``x(t_i)``; the covariance ``X(t_i)`` of Eq. 14 is that
of the state right after the maneuver at ``t_i`` (it contains the maneuver's execution error
``B U B^T``), so the drift starts from the post-maneuver mean ``y_i = x_i + B_i u_i``, which
also makes the Monte Carlo check of :mod:`.montecarlo` physically meaningful (navigate,
burn with Gates errors, then lose control). The pre-maneuver state at ``t_i`` lies on the
drift arc of node ``i - 1`` (at ``tau = Delta t``), so it is guarded as well whenever
``T_safety >= Delta t``. The final node ``N`` (fixed, no maneuver) carries no constraint.

Constraint-violation metric (Eq. 7). Printed as ``C = 1 if M* + beta <= 0``, which would
count satisfied nodes; the text ("C_ART(t_1) = 0" means passively safe, "higher values ...
more frequent constraint violations") fixes the intended reading ``C_i = 1`` when the
constraint with margin is VIOLATED, ``h_i > tol``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scpformer.dynamics.orbits import propagate_kepler, propagate_mean_j2
from scpformer.dynamics.roe import psi_matrix, stm_j2, stm_kepler
from scpformer.dynamics.uncertainty import covariance_history, propagate_covariance
from scpformer.problems.rendezvous.problem import LinearModel
from scpformer.problems.rendezvous.problem import linear_model as _rendezvous_linear_model
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.scenario import check_mode

_TINY_DISTANCE = 1e-12  # normalized distance below which the gradient direction is undefined
VIOLATION_TOL = 1e-6  # default tolerance of Eq. 7 on h (normalized distance)


# ======================================================================================
# linear model and drift geometry (depend on the instance only: built once per solve)
# ======================================================================================
def linear_model(instance: RobustInstance) -> LinearModel:
    """STMs, input matrices and ``Psi`` at all nodes: the rendezvous family's builder.

    :func:`scpformer.problems.rendezvous.problem.linear_model` reads only ``times()``,
    ``target.oe`` and ``scenario.j2``, which a :class:`RobustInstance` provides.
    """
    return _rendezvous_linear_model(instance)  # type: ignore[arg-type]


def drift_offsets(t_safety_s: float, n_safety: int) -> np.ndarray:
    """``tau_j`` [s]: ``n_safety`` samples of ``[0, T_safety]`` (one, ``0``, if ``T = 0``)."""
    if t_safety_s <= 0.0:
        return np.zeros(1)
    return np.linspace(0.0, t_safety_s, max(int(n_safety), 2))


@dataclass(frozen=True)
class DriftGeometry:
    """Everything about the free-drift arcs that does not depend on the iterate."""

    tau: np.ndarray  # (S,) drift offsets tau_j [s]
    Phi: np.ndarray  # (N, S, 6, 6) Phi(t_i + tau_j, t_i)
    Psi: np.ndarray  # (N, S, 6, 6) Psi(t_i + tau_j)
    G: np.ndarray  # (N, S, 3, 6) E_i D Psi Phi [1/m]
    E: np.ndarray  # (N, 3, 3) E_i = P^(1/2) of the guarding ellipsoid [1/m]
    use_ae: np.ndarray  # (N,) bool: node guarded by the approach ellipsoid (else the KOZ)


def drift_geometry(instance: RobustInstance, t_safety_s: float | None = None) -> DriftGeometry:
    """Sample the drift arcs of nodes ``0 .. N-1`` (vectorized; ~5 ms for 100 x 20 samples).

    ``t_safety_s`` defaults to the scenario's ``T_safety``; ``0`` gives collision avoidance.
    """
    sc = instance.scenario
    t_safety = instance.t_safety_s if t_safety_s is None else float(t_safety_s)
    tau = drift_offsets(t_safety, sc.n_safety)
    t = instance.times()[:-1]
    oe0 = instance.target.oe.to_array()
    propagate, stm = (propagate_mean_j2, stm_j2) if sc.j2 else (propagate_kepler, stm_kepler)
    oe_nodes = propagate(oe0, t)  # (N, 6)
    oe_drift = propagate(oe0, t[:, None] + tau[None, :])  # (N, S, 6)
    Phi = stm(oe_nodes[:, None, :], tau[None, :])  # (N, S, 6, 6)
    Psi = psi_matrix(oe_drift)
    E = sc.ellipsoid_E()[:-1]
    G = np.einsum("irs,ijsk,ijkl->ijrl", E, Psi[..., :3, :], Phi)
    use_ae = np.arange(sc.n_nodes) < sc.n_ae_to_koz
    return DriftGeometry(tau=tau, Phi=Phi, Psi=Psi, G=G, E=E, use_ae=use_ae)


# ======================================================================================
# evaluation at an iterate (batched over nodes and drift samples)
# ======================================================================================
@dataclass(frozen=True)
class SafetyEvaluation:
    """Passive-safety constraint of every node at one trajectory (see the module docstring)."""

    h: np.ndarray  # (N,) 1 + beta_hat - d*: <= 0 is safe with the margin
    h_mean: np.ndarray  # (N,) 1 - d*: the mean-state constraint (beta = 0)
    beta: np.ndarray  # (N,) beta_hat = q sqrt(a_hat^T X a_hat), normalized margin
    d: np.ndarray  # (N, S) normalized distances of the drift samples
    j_star: np.ndarray  # (N,) index of t* in tau
    a_hat: np.ndarray  # (N, 6) gradient of d* w.r.t. y_i at the reference
    c_u: np.ndarray  # (N, 3) B_i^T a_hat_i: gradient w.r.t. u_i
    X: np.ndarray | None  # (N, 6, 6) covariance X(t_i) of Eq. 14 (None: deterministic)
    y: np.ndarray  # (N, 6) post-maneuver states

    @property
    def b_ps(self) -> np.ndarray:
        """``b_ps`` of Eq. 16: the normalized distance at ``t*``."""
        return np.take_along_axis(self.d, self.j_star[:, None], axis=1)[:, 0]

    @property
    def eq15(self) -> np.ndarray:
        """Left-hand side of Eq. 15 at the reference, ``b_ps (1 - b_ps) + beta``, (N,)."""
        b = self.b_ps
        return b * (1.0 - b) + b * self.beta

    @property
    def eq15_mean(self) -> np.ndarray:
        """Eq. 15 without margin, ``M*(x) = b_ps (1 - b_ps)``, (N,)."""
        b = self.b_ps
        return b * (1.0 - b)


def evaluate_safety(
    geometry: DriftGeometry,
    model: LinearModel,
    x: np.ndarray,
    u: np.ndarray,
    instance: RobustInstance,
    mode: str,
) -> SafetyEvaluation:
    """Eqs. 14-16 at ``(x, u)`` for every node at once; ``mode="deterministic"`` sets ``X = 0``.

    Parameters
    ----------
    geometry
        From :func:`drift_geometry` (``T_safety`` and the ellipsoids).
    model
        Linear model of the instance (``B``, ``Phi``, ``Psi`` at the nodes).
    x, u
        States (N+1, 6) [m] and impulses (N, 3) [m/s].
    instance
        Supplies the uncertainty model and ``Delta``.
    mode
        ``"deterministic"`` or ``"chance"``.
    """
    check_mode(mode)
    n = u.shape[0]
    y = x[:n] + np.einsum("ikl,il->ik", model.B, u)  # (N, 6)
    r = np.einsum("ijrl,il->ijr", geometry.G, y)  # (N, S, 3)
    d = np.linalg.norm(r, axis=-1)  # (N, S)
    j_star = np.argmin(d, axis=1)
    idx = np.arange(n)
    d_star = d[idx, j_star]
    G_star = geometry.G[idx, j_star]  # (N, 3, 6)
    r_star = r[idx, j_star] / np.maximum(d_star, _TINY_DISTANCE)[:, None]
    a_hat = np.einsum("ir,irl->il", r_star, G_star)  # (N, 6)
    c_u = np.einsum("ikl,ik->il", model.B, a_hat)  # (N, 3)
    X, beta = None, np.zeros(n)
    if mode == "chance":
        unc = instance.uncertainty
        hist = covariance_history(x[:n], u, model.Phi, model.B, model.Psi[:n], unc)
        X = hist.X
        var = np.einsum("ik,ikl,il->i", a_hat, X, a_hat)
        beta = unc.q * np.sqrt(np.maximum(var, 0.0))
    h_mean = 1.0 - d_star
    return SafetyEvaluation(
        h=h_mean + beta, h_mean=h_mean, beta=beta, d=d, j_star=j_star, a_hat=a_hat, c_u=c_u,
        X=X, y=y,
    )  # fmt: skip


def covariance_at_tstar(geometry: DriftGeometry, ev: SafetyEvaluation) -> np.ndarray | None:
    """``X(t*) = Phi(t*, t_i) X(t_i) Phi^T`` (Eq. 14, second line), (N, 6, 6), or None."""
    if ev.X is None:
        return None
    Phi = geometry.Phi[np.arange(ev.j_star.size), ev.j_star]
    return propagate_covariance(ev.X, Phi)


def violation_flags(h: np.ndarray, tol: float = VIOLATION_TOL) -> np.ndarray:
    """``C(t_i)`` of Eq. 7: 1 where the constraint (with its margin) is violated, (N,) ints."""
    return (np.asarray(h, dtype=float) > tol).astype(int)


def constraint_violation_budget(h: np.ndarray, tol: float = VIOLATION_TOL) -> np.ndarray:
    """Constraint-violation budget ``C(t_i) = sum_{j >= i} C_j`` (Eqs. 5, 7), (N+1,) ints.

    The last entry (node ``N``, no constraint) is 0, so ``C`` aligns with the states.
    """
    flags = violation_flags(h, tol)
    return np.append(np.cumsum(flags[::-1])[::-1], 0)


def trajectory_violations(
    instance: RobustInstance,
    x: np.ndarray,
    u: np.ndarray,
    mode: str = "chance",
    tol: float = VIOLATION_TOL,
) -> np.ndarray:
    """Eq. 7 budget of ANY trajectory ``(x, u)`` of the instance (e.g. a warm start), (N+1,)."""
    ev = evaluate_safety(drift_geometry(instance), linear_model(instance), x, u, instance, mode)
    return constraint_violation_budget(ev.h, tol)
