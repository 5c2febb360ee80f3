"""The SCvx* subproblem of Eq. 17 as one parametric (DPP) cvxpy problem, compiled once per N.

Notation: nodes ``i = 0 .. N`` (see :mod:`.scenario`); variables ``X`` (N+1, 6) scaled mean
ROE [m] and ``U = 1e3 u`` (N, 3) [mm/s] (so that ``Phi B U`` is of order metres like ``X``)::

    min   sum_i |u_i|_2 + mu^T zeta + w/2 |zeta|^2                    (Eq. 17, J_pen of Oguri)
    s.t.  x_{i+1} = Phi_i x_i + Phi_i B_i u_i + f_i           i = 0 .. N-1
          x_0 = x_init,  x_N = x_f
          c_i - a_i^T x_i - e_i^T u_i <= zeta_i,  zeta >= 0   i = 0 .. N-1   (Eq. 15 / b_ps)
          |x_i - x_bar_i|_inf <= r                            i = 1 .. N-1
          |u_i - u_bar_i|_inf <= s_u r                        i = 0 .. N-1

with ``a_i = a_hat_i``, ``e_i = B_i^T a_hat_i`` and ``c_i = 1 + beta_hat_i`` from
:func:`.safety.evaluate_safety` at the reference. The dynamics are the STM about the target
(``f_i = 0``) or the first-order expansion of the nonlinear mean-element flow about the
reference, ``Phi_i`` its Jacobian and ``f_i = F(y_bar_i) - Phi_i y_bar_i`` (see
:mod:`.problem`). With ``n_rows = K > 1`` each node gets the
rows of its ``K`` worst drift samples, all bounded by the node's one buffer ``zeta_i``: the
cutting-plane model ``max_k`` of the linearizations of ``h_i = max_j h_ij``, which anticipates
a switch of ``t*`` to a neighbouring sample (``K = 1`` is Eq. 17 as printed).

The buffers ``zeta`` of the inequality rows are the virtual buffers of Eq. 17 (the
dynamics and boundary conditions are linear, hence exact, so SCvx* has no equality
constraints ``g`` here). The state trust region skips the two fixed boundary nodes, but a
reference that misses ``x_f`` by more than the last impulses can reach within the radius (a
learned warm start, kilometres off) still gives an infeasible subproblem; SCvx* then grows the
radius (``SCvxStarParameters.expand_on_infeasible``). ``s_u``
is 1 m/s per unit of ``r`` by default (the paper's single radius ``rho`` for both).

Proximal term (not in Eq. 17). The fuel cost is degenerate (many plans cost within 1e-5 m/s
of each other) and an interior-point solver returns the centre of the optimal face, which can
lie hundreds of metres from the reference for a negligible predicted decrease; the
minimum-separation instant ``t*`` then jumps and SCvx* rejects the step. A small
``PROX_WEIGHT (|X - X_bar|^2 + |U - U_bar|^2)`` picks the optimal point nearest the reference
(1 m on every state costs 6e-6 m/s). It vanishes at ``z = z_bar``, so it changes neither the
fixed points of SCvx* nor its ratio test (``L`` is evaluated without it).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from scpformer.scp.conic import (
    SOLVED,
    assign,
    batched_matvec,
    compiled,
    solve_timed,
)
from scpformer.scp.scvx_star import PenaltyTerm

U_SCALE = 1e3  # decision variable U = U_SCALE * u (mm/s)
PROX_WEIGHT = 1e-10  # proximal weight [m/s per m^2 and per (mm/s)^2], see the module docstring


@dataclass(frozen=True)
class ConicResult:
    """One conic solve; ``status`` is cvxpy's status string (or ``solver_error: ...``)."""

    status: str
    x: np.ndarray | None  # (N+1, 6) [m]
    u: np.ndarray | None  # (N, 3) [m/s]
    zeta: np.ndarray | None  # (N,) virtual buffers
    cost: float  # sum |u_i|_2 [m/s]
    solver_time: float  # s inside the conic solver

    @property
    def ok(self) -> bool:
        """Optimal or optimal_inaccurate with values."""
        return self.status in SOLVED and self.x is not None


class SafetySubproblem:
    """Eq. 17 for ``n_nodes`` impulses; parameters are written before each re-solve."""

    def __init__(self, n_nodes: int, n_rows: int = 1) -> None:
        n = self.n_nodes = int(n_nodes)
        k = self.n_rows = int(n_rows)
        if n < 2 or k < 1:
            raise ValueError(f"need n_nodes >= 2 and n_rows >= 1, got {n_nodes}, {n_rows}")
        P = cp.Parameter
        self.phi = P((n, 36), name="Phi")  # row-major Phi_i
        self.gamma = P((n, 18), name="Phi_B")  # row-major Phi_i B_i / U_SCALE
        self.f = P((n, 6), name="f")  # affine term of linearized nonlinear dynamics [m]
        self.x_init = P(6, name="x_init")
        self.x_final = P(6, name="x_f")
        self.a_x = P((n * k, 6), name="a_hat")  # gradients of d_ij w.r.t. x_i [1/m]
        self.a_u = P((n * k, 3), name="B_T_a_hat")  # gradients w.r.t. U_i (already / U_SCALE)
        self.c = P(n * k, name="one_plus_beta")  # 1 + beta_hat_ij
        self.x_ref = P((n + 1, 6), name="x_bar")
        self.u_ref = P((n, 3), name="U_bar")
        self.u_radius = P(nonneg=True, name="r_u")  # U_SCALE * s_u * r
        self.term = PenaltyTerm(n_g=0, n_h=n)
        self.X = cp.Variable((n + 1, 6), name="X")
        self.U = cp.Variable((n, 3), name="U")
        self.problem = self._build()

    def _build(self) -> cp.Problem:
        X, U, n, term = self.X, self.U, self.n_nodes, self.term
        dynamics = batched_matvec(self.phi, X[:-1], 6, 6) + batched_matvec(self.gamma, U, 6, 3)
        dynamics = dynamics + self.f
        node = np.repeat(np.arange(n), self.n_rows)  # row -> node, K rows per node
        X_rows, U_rows = (X[node, :], U[node, :]) if self.n_rows > 1 else (X[:n], U)
        safety = (
            self.c
            - cp.sum(cp.multiply(self.a_x, X_rows), axis=1)
            - cp.sum(cp.multiply(self.a_u, U_rows), axis=1)
        )
        zeta = term.zeta[node] if self.n_rows > 1 else term.zeta
        constraints = [
            X[1:] == dynamics,
            X[0] == self.x_init,
            X[n] == self.x_final,
            safety <= zeta,
            X[1:n] - self.x_ref[1:n] <= term.r,  # |.|_inf <= r as two linear inequalities
            self.x_ref[1:n] - X[1:n] <= term.r,  # (cp.abs would add an auxiliary per entry)
            U - self.u_ref <= self.u_radius,
            self.u_ref - U <= self.u_radius,
        ]
        # |X - X_bar|^2 + |U - U_bar|^2 up to a constant, written without the differences so
        # that canonicalization adds no auxiliary variable per entry (the solver sees P directly)
        proximal = (
            cp.sum_squares(X[1:n])
            - 2.0 * cp.sum(cp.multiply(self.x_ref[1:n], X[1:n]))
            + cp.sum_squares(U)
            - 2.0 * cp.sum(cp.multiply(self.u_ref, U))
        )
        cost = cp.sum(cp.norm(U, 2, axis=1)) / U_SCALE + term.expression
        cost = cost + PROX_WEIGHT * proximal
        return cp.Problem(cp.Minimize(cost), constraints)

    # -- parameter updates ---------------------------------------------------------------
    def set_dynamics(
        self,
        Phi: np.ndarray,
        Gamma: np.ndarray,
        x_init: np.ndarray,
        x_final: np.ndarray,
        f: np.ndarray | None = None,
    ) -> None:
        """Write ``Phi_i`` (N, 6, 6), ``Phi_i B_i`` (N, 6, 3) [s], the boundary ROE [m] and the
        affine terms ``f_i`` (N, 6) [m] (zeros when ``None``)."""
        n = self.n_nodes
        assign(self.phi, np.asarray(Phi, dtype=float).reshape(n, 36))
        assign(self.gamma, np.asarray(Gamma, dtype=float).reshape(n, 18) / U_SCALE)
        assign(self.f, np.zeros((n, 6)) if f is None else f)
        assign(self.x_init, x_init)
        assign(self.x_final, x_final)

    def set_iterate(
        self,
        x_ref: np.ndarray,
        u_ref: np.ndarray,
        a_x: np.ndarray,
        a_u: np.ndarray,
        c: np.ndarray,
        *,
        mu: np.ndarray,
        w: float,
        r: float,
        u_trust_scale: float,
    ) -> None:
        """Write the reference, the linearized safety rows (N, K, ...), multipliers, weight and
        radius."""
        assign(self.x_ref, x_ref)
        assign(self.u_ref, U_SCALE * np.asarray(u_ref, dtype=float))
        assign(self.a_x, np.asarray(a_x, dtype=float).reshape(-1, 6))
        assign(self.a_u, np.asarray(a_u, dtype=float).reshape(-1, 3) / U_SCALE)
        assign(self.c, np.reshape(c, -1))
        assign(self.u_radius, U_SCALE * u_trust_scale * float(r))
        self.term.assign(lambda_=np.zeros(0), mu=mu, w=w, r=r)

    # -- solve ---------------------------------------------------------------------------
    def solve(self, solver: str = "clarabel") -> ConicResult:
        """Solve with the current parameters; a failing solve is a status, never a raise."""
        call = solve_timed(self.problem, solver, reuse=True)
        if not call.solved or self.X.value is None:
            return ConicResult(call.status, None, None, None, math.nan, call.solver_time)
        u = self.U.value / U_SCALE
        _, zeta = self.term.buffers()
        return ConicResult(
            status=call.status,
            x=self.X.value.copy(),
            u=u,
            zeta=zeta,
            cost=float(np.linalg.norm(u, axis=1).sum()),
            solver_time=call.solver_time,
        )


@functools.lru_cache(maxsize=8)
def compiled_safety_subproblem(
    n_nodes: int, solver: str = "clarabel", n_rows: int = 1
) -> SafetySubproblem:
    """The process-wide Eq. 17 subproblem per ``N``, ``K`` and solver (disk-cached)."""
    key = f"robust-rendezvous-eq17-N{n_nodes}-K{n_rows}-{solver}"
    return compiled(key, lambda: SafetySubproblem(n_nodes, n_rows), solver, __file__)
