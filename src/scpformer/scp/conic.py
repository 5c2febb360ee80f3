"""The one place that knows which conic solvers scpformer drives and how a solve is timed.

Every convex subproblem in the package is a parametric ``cvxpy.Problem`` built once and
canonicalized once (DESIGN: "build the convex subproblem once, update numbers in the loop").
This module holds what they share:

* :data:`SOLVERS` -- the supported solver names and their cvxpy constants, with
  :func:`check_solver` giving the one error message for an unknown name;
* :func:`canonicalize` -- run cvxpy's parameter-to-data compilation ahead of the first solve
  (the result is what :func:`scpformer.cache.cached_pickle` keeps on disk);
* :func:`solve_timed` -- cvxpy's three stages run by hand (cached parameter map -> conic solver
  -> unpack), so that the conic solver call is timed on its own with the same clock as the
  wall time around it; a failing solve is a status, never a raise;
* :func:`batched_matvec` -- ``K`` small matrix-vector products as one affine expression,
  vectorized over the horizon.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import cvxpy as cp

SOLVERS: dict[str, str] = {"clarabel": cp.CLARABEL, "ecos": cp.ECOS, "qoco": cp.QOCO}
SOLVED = (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)  # statuses with a usable primal solution


def check_solver(solver: str, what: str = "solver") -> str:
    """Return ``solver`` if scpformer drives it, else raise ``ValueError`` naming the choices."""
    if solver not in SOLVERS:
        raise ValueError(f"{what} must be one of {', '.join(SOLVERS)}, got {solver!r}")
    return solver


def canonicalize(problem: cp.Problem, solver: str) -> None:
    """Compile ``problem`` for ``solver`` now, so that the first solve only maps parameters."""
    problem.get_problem_data(SOLVERS[check_solver(solver)], solver_opts={})


@dataclass(frozen=True)
class ConicCall:
    """Outcome of one :func:`solve_timed` call.

    ``status`` is cvxpy's status string, or ``"solver_error: ..."`` when the solver raised;
    the variables of the problem hold the solution only when ``solved`` is true.
    """

    status: str
    solver_time: float  # s inside the conic solver call (data in, raw solution out)
    wall_time: float  # s from the parameter values to the unpacked solution

    @property
    def solved(self) -> bool:
        """Optimal or optimal-inaccurate (the caller flags the latter through ``status``)."""
        return self.status in SOLVED


def solve_timed(problem: cp.Problem, solver: str) -> ConicCall:
    """Solve ``problem`` with its current parameter values and time the solver call alone."""
    name = SOLVERS[check_solver(solver)]
    start = time.perf_counter()
    solver_time = 0.0
    try:
        with warnings.catch_warnings():  # "inaccurate" is reported as a status instead
            warnings.simplefilter("ignore", UserWarning)
            data, chain, inverse = problem.get_problem_data(name, solver_opts={})
            t0 = time.perf_counter()
            raw = chain.solve_via_data(problem, data, False, False, {})
            solver_time = time.perf_counter() - t0
            problem.unpack_results(raw, chain, inverse)
    except cp.SolverError as err:
        return ConicCall(f"solver_error: {err}", solver_time, time.perf_counter() - start)
    return ConicCall(str(problem.status), solver_time, time.perf_counter() - start)


def batched_matvec(M: cp.Expression, V: cp.Expression, rows: int, cols: int) -> cp.Expression:
    """``out[k, r] = sum_j M[k, r*cols + j] V[k, j]`` for all k at once.

    ``M`` is a parameter of shape (K, rows*cols) holding row-major (rows, cols) matrices, ``V``
    an affine expression of shape (K, cols); the result has shape (K, rows). It is built from
    ``cols`` elementwise products, which cvxpy canonicalizes far faster than ``K`` separate
    ``M_k @ v_k`` terms.
    """
    out = None
    for j in range(cols):
        term = cp.multiply(M[:, j::cols], V[:, j : j + 1])  # (K, rows) * (K, 1) broadcast
        out = term if out is None else out + term
    return out
