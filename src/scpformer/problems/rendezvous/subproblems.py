"""The three rendezvous OCPs as parametric cvxpy problems, compiled once per (kind, N, N_wp).

Notation: nodes ``k = 0 .. N`` (see :mod:`.scenario`), state ``x_k = a dalpha(t_k)`` [m]
(scaled mean ROE), impulse ``dv_k`` [m/s] in RTN. Decision variables ``X (N+1, 6)`` and
``U = 1e3 dv (N, 3)`` (mm/s, so that ``Phi B U`` is of order metres like ``X``).

* ``"tpbvp"`` (Problem 1, Eq. 11)::

      min  sum_k |dv_k|_2
      s.t. x_{k+1} = Phi_k x_k + Phi_k B_k dv_k        k = 0..N-1   (Eq. 10)
           x_0 = x_init,  x_N = x_dock

* ``"convex"`` (Problem 2, Eqs. 12-13): adds the waypoint ``x_{N_wp} = x_wp`` and the approach
  cone ``|A_k x_k + b|_2 <= c_k^T x_k + d`` for ``k = N_wp .. N-1``.
* ``"scp"`` (the SCP subproblem of Problem 3, Eqs. 15-17): adds the linearized keep-out
  constraint ``a_k^T x_k >= b_k`` and the trust region ``|x_k - x_bar_k|_2 <= zeta`` for
  ``k = 0 .. N_wp``.

``n_waypoint <= 0`` poses the remaining horizon after the waypoint (closed-loop re-planning in
the final approach, :attr:`~.scenario.RendezvousScenario.waypoint_passed`): no waypoint row,
the cone for ``k = 1 .. N-1`` (``x_0`` is given), and no keep-out cut or trust region
(``"scp"`` is then Problem 2 again, which the SCP solves in one or two iterations). All such
problems of ``N`` impulses share one structure, compiled under ``n_waypoint = 0``.

``Psi x = y`` boundary conditions (Eq. 12, 14) are imposed as ``x = Psi^{-1} y`` (``Psi`` is
invertible), computed by the caller. Every number that depends on the instance or on the SCP
iterate is a ``cvxpy.Parameter`` (DPP): the problem is canonicalized once per structure and
process (and cached on disk, see :func:`scpformer.cache.cached_pickle`); an iteration only
writes parameter values. The per-node products ``Phi_k x_k`` are written as six column-wise
elementwise products over the whole horizon, so the expression tree does not grow with N.
"""

from __future__ import annotations

import functools

import cvxpy as cp
import numpy as np

from scpformer.scp.conic import (
    ConicSettings,
    SubproblemSolution,
    assign,
    batched_matvec,
    check_solver,
    compiled,
    solve_timed,
)

KINDS = ("tpbvp", "convex", "scp")
INACCURATE = cp.OPTIMAL_INACCURATE
U_SCALE = 1e3  # decision variable U = U_SCALE * dv (mm/s)


class RendezvousSubproblem:
    """Parametric convex problem of one kind for ``n_nodes`` impulses; see the module docstring."""

    def __init__(self, kind: str, n_nodes: int, n_waypoint: int) -> None:
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        if not (1 <= n_waypoint <= n_nodes - 2 or (n_waypoint <= 0 and n_nodes >= 2)):
            raise ValueError(
                "n_waypoint must lie in [1, n_nodes - 2], or be <= 0 (the waypoint passed) with "
                f"n_nodes >= 2, got n_waypoint = {n_waypoint}, n_nodes = {n_nodes}"
            )
        self.passed = n_waypoint <= 0
        self.kind, self.n_nodes, self.n_waypoint = kind, n_nodes, max(n_waypoint, 0)
        n, kw = n_nodes, self.n_waypoint
        self.cone_start = 1 if self.passed else kw  # passed: x_0 is given, no row there
        n_cone, n_koz = n - self.cone_start, (0 if self.passed else kw + 1)
        P = cp.Parameter
        self.phi = P((n, 36), name="Phi")  # row-major Phi_k
        self.gamma = P((n, 18), name="Phi_B")  # row-major Phi_k B_k / U_SCALE
        self.x_init = P(6, name="x_init")
        self.x_dock = P(6, name="x_dock")
        self.x_wp = P(6, name="x_wp")
        self.cone_A = P((n_cone, 18), name="A_ac")  # row-major D Psi_k, k = cone_start..N-1
        self.cone_c = P((n_cone, 6), name="c_ac")
        self.cone_b = P(3, name="b_ac")
        self.cone_d = P(name="d_ac")
        if n_koz:
            self.koz_a = P((n_koz, 6), name="a_koz")
            self.koz_b = P(n_koz, name="b_koz")
            self.x_ref = P((n_koz, 6), name="x_bar")
        self.zeta = P(nonneg=True, name="zeta")
        self.X = cp.Variable((n + 1, 6), name="X")
        self.U = cp.Variable((n, 3), name="U")
        self.problem = self._build()

    def _build(self) -> cp.Problem:
        X, U, kw, n = self.X, self.U, self.n_waypoint, self.n_nodes
        dynamics = batched_matvec(self.phi, X[:-1], 6, 6) + batched_matvec(self.gamma, U, 6, 3)
        constraints = [X[1:] == dynamics, X[0] == self.x_init, X[n] == self.x_dock]
        if self.kind in ("convex", "scp"):
            kc = self.cone_start
            position = batched_matvec(self.cone_A, X[kc:n], 3, 6)  # D Psi_k x_k, (n_cone, 3)
            lhs = cp.norm(position + self.cone_b[None, :], 2, axis=1)
            rhs = cp.sum(cp.multiply(self.cone_c, X[kc:n]), axis=1) + self.cone_d
            waypoint = [] if self.passed else [X[kw] == self.x_wp]
            constraints += [*waypoint, lhs <= rhs]
        if self.kind == "scp" and not self.passed:
            constraints += [
                cp.sum(cp.multiply(self.koz_a, X[: kw + 1]), axis=1) >= self.koz_b,  # Eq. 15
                cp.norm(X[: kw + 1] - self.x_ref, 2, axis=1) <= self.zeta,  # Eq. 17
            ]
        cost = cp.sum(cp.norm(U, 2, axis=1)) / U_SCALE
        return cp.Problem(cp.Minimize(cost), constraints)

    # -- parameter updates ---------------------------------------------------------------
    def set_dynamics(
        self, Phi: np.ndarray, Gamma: np.ndarray, x_init: np.ndarray, x_dock: np.ndarray
    ) -> None:
        """Write ``Phi_k`` (N, 6, 6), ``Phi_k B_k`` (N, 6, 3) [s] and the boundary ROE [m]."""
        n = self.n_nodes
        assign(self.phi, np.asarray(Phi).reshape(n, 36))
        assign(self.gamma, np.asarray(Gamma).reshape(n, 18) / U_SCALE)
        assign(self.x_init, x_init)
        assign(self.x_dock, x_dock)

    def set_final_approach(
        self, x_wp: np.ndarray, A: np.ndarray, c: np.ndarray, b: np.ndarray, d: float
    ) -> None:
        """Write the waypoint ROE and the cone rows of Eq. 13 for nodes ``N_wp .. N-1``
        (once the waypoint is passed: ``x_wp`` is not used, the rows are nodes ``1 .. N-1``).

        ``A`` (n_cone, 3, 6) = ``D Psi_k``, ``c`` (n_cone, 6) = ``n^T D Psi_k / cos gamma``,
        ``b`` (3,) = ``-apex``, ``d`` = ``-n^T apex / cos gamma``.
        """
        if not self.passed:
            assign(self.x_wp, x_wp)
        assign(self.cone_A, np.asarray(A).reshape(A.shape[0], 18))
        assign(self.cone_c, c)
        assign(self.cone_b, b)
        assign(self.cone_d, d)

    def set_keep_out(self, a: np.ndarray, b: np.ndarray, x_ref: np.ndarray, zeta: float) -> None:
        """Write the cut ``a_k^T x_k >= b_k`` (Eqs. 15-16) and the trust region (Eq. 17);
        nothing once the waypoint is passed (no keep-out node)."""
        if self.passed:
            return
        assign(self.koz_a, a)
        assign(self.koz_b, b)
        assign(self.x_ref, x_ref)
        assign(self.zeta, zeta)

    # -- solve ---------------------------------------------------------------------------
    def solve(
        self, solver: str = "clarabel", settings: ConicSettings | None = None
    ) -> SubproblemSolution:
        """Solve with the current parameter values; a failing solve is a status, not a raise.

        ``settings`` maps a solver name to settings other than the solver's defaults. See
        :func:`scpformer.scp.conic.solve_timed` for how the solver call is timed.
        """
        call = solve_timed(self.problem, solver, settings=settings)
        if not call.solved or self.X.value is None:
            return SubproblemSolution.failed(call.status, call.wall_time, call.solver_time)
        dv = self.U.value / U_SCALE
        return SubproblemSolution(
            status=call.status,
            x=self.X.value.copy(),
            u=dv,
            cost=float(np.linalg.norm(dv, axis=1).sum()),
            solver_time=call.solver_time,
            wall_time=call.wall_time,
        )


def compiled_subproblem(
    kind: str, n_nodes: int, n_waypoint: int, solver: str = "clarabel"
) -> RendezvousSubproblem:
    """The process-wide subproblem per structure, canonicalized for ``solver``.

    Canonicalization takes about 1.3 s for ``"scp"`` and 0.3 s for the others at N = 100; it is
    cached on disk keyed by the structure, the solver, the cvxpy and scpformer versions and this
    module's source. Every ``n_waypoint <= 0`` (the waypoint passed) is one structure.
    """
    return _compiled_subproblem(kind, n_nodes, max(n_waypoint, 0), solver)


@functools.lru_cache(maxsize=32)
def _compiled_subproblem(
    kind: str, n_nodes: int, n_waypoint: int, solver: str
) -> RendezvousSubproblem:
    check_solver(solver)
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    key = f"rendezvous-{kind}-N{n_nodes}-wp{n_waypoint}-{solver}"
    return compiled(key, lambda: RendezvousSubproblem(kind, n_nodes, n_waypoint), solver, __file__)
