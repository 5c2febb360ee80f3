"""A least-change second-order correction that needs no conic solve.

SCvx's second-order correction (:func:`scpformer.scp.scvx._wants_correction`) re-solves the
convex subproblem with its dynamics shifted by the candidate's defects. Near a solution the
step it makes is small and leaves the active set of the candidate as it is, which makes it,
to first order, the classical SOC step of SQP (Nocedal & Wright, Sec. 15.5, Eq. 15.35):
the least change ``Delta`` of the candidate ``z*`` that cancels its defects ``d`` along the
linearization at ``z*`` while keeping the boundary conditions and the rows that are tight at
``z*``:

    min  sum_i (Delta_i / s_i)^2
    s.t. Delta x_{k+1} - A_k Delta x_k - Bm_k Delta u_k - Bp_k Delta u_{k+1} - S_k Delta sigma
             = -d_k                                           (Eq. 10 at z*, every interval)
         Delta x_0 = 0,  Delta x_N[fixed terminal columns] = 0   (Eqs. 3b-3i)
         grad g_j(z*) . Delta = 0  for every row j with g_j(z*) >= -tol   (Eqs. 5-6)

with ``s`` the trust-region scales. Its solution is ``Delta = D C^T (C D C^T)^-1 r`` with
``D = diag(s^2)``: one sparse factorization of a matrix of about 14 N rows, a few
milliseconds instead of an interior-point solve. The gradients of the inequality rows are
central differences of :func:`~scpformer.problems.pdg6dof.constraints.constraint_values`,
node by node, so the correction follows whatever the constraint module defines.

A correction that leaves a convex row violated (beyond ``tolerance``) or the final-time
bounds is refused (``None``): the conic correction, which keeps every row, then runs.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.subproblem import fixed_terminal_columns, trust_region_scales
from scpformer.scp.discretization import FOHDiscretization
from scpformer.scp.solution import Trajectory

N_X, N_U = 14, 3


class LeastChangeCorrection:
    """The least-change correction of the module docstring about one candidate ``z*``.

    Built once per candidate: the constraint rows ``C`` (Eq. 10 at ``z*``, the boundary
    conditions, the gradients of the rows tight at ``z*``) and the factorization of
    ``C D C^T``. :meth:`step` then maps any iterate ``z`` with its defects to
    ``z + D C^T (C D C^T)^-1 r(z)``, where ``r`` holds minus its defects and minus the values
    of the rows tight at ``z*``: the first step from ``z*`` is the SOC step, further steps
    (a chord iteration with the same factorization) cancel what the first one left.

    Parameters
    ----------
    instance
        The problem parameters (constraint bounds, final-time bounds).
    disc
        The FOH linearization at ``z``.
    z
        The candidate ``z*``.
    fix_roll
        Whether the terminal roll is fixed (which terminal columns are held).
    tight_tol
        A row with ``g >= -tight_tol`` at ``z*`` is held at ``g = 0``.
    """

    def __init__(
        self,
        instance: PDGInstance,
        disc: FOHDiscretization,
        z: Trajectory,
        fix_roll: bool,
        tight_tol: float,
    ) -> None:
        self.instance = instance
        n = z.x.shape[0]
        C_dyn = _dynamics_rows(disc, z.x)
        C_act, self._active = _active_rows(instance, z, tight_tol)
        C = sp.vstack([C_dyn, C_act, _fixed_rows(n, fix_roll)]).tocsc()
        self._n_dynamics, self._n_active = C_dyn.shape[0], C_act.shape[0]
        self._n_rows = C.shape[0]
        self._C = C
        self._s2 = _metric(instance, n)
        self._solve = _factorized(C, self._s2)

    def step(self, z: Trajectory, defects: np.ndarray, values: np.ndarray) -> Trajectory | None:
        """``z`` moved to cancel its ``defects`` (K, 14) and the held rows of its ``values``
        (:func:`~scpformer.problems.pdg6dof.constraints.constraint_values`); ``None`` when the
        linear algebra fails."""
        n = z.x.shape[0]
        r = np.zeros(self._n_rows)
        r[: self._n_dynamics] = -np.asarray(defects).ravel()
        r[self._n_dynamics : self._n_dynamics + self._n_active] = -values[self._active]
        y = self._solve(r)
        if y is None:
            return None
        delta = self._s2 * (self._C.T @ y)
        if not np.isfinite(delta).all():
            return None
        return Trajectory(
            x=z.x + delta[: n * N_X].reshape(n, N_X),
            u=z.u + delta[n * N_X : n * (N_X + N_U)].reshape(n, N_U),
            p=np.asarray(z.p, dtype=float) + delta[-1],
        )

    def keeps_convex_rows(self, z: Trajectory, values: np.ndarray, tolerance: float = 1e-7) -> bool:
        """No convex row of Eqs. 5-6 (of ``z``'s ``values``) and neither final-time bound
        violated beyond ``tolerance`` at ``z``."""
        c = self.instance.constants
        tf = float(z.p[0])
        return bool(
            values[list(con.CONVEX_ROWS)].max() <= tolerance
            and c.tf_min - tolerance <= tf <= c.tf_max + tolerance
        )


def _x_columns(nodes: np.ndarray) -> np.ndarray:
    """Columns of the states of ``nodes`` in the stacked ``(x, u, sigma)``: (len, 14)."""
    return nodes[:, None] * N_X + np.arange(N_X)


def _u_columns(nodes: np.ndarray, n: int) -> np.ndarray:
    """Columns of the thrust of ``nodes``: (len, 3)."""
    return n * N_X + nodes[:, None] * N_U + np.arange(N_U)


def _dynamics_rows(disc: FOHDiscretization, x: np.ndarray) -> sp.csr_array:
    """Eq. 10 at ``z*`` for the change, ``C_dyn Delta = -d``: K * 14 rows, row (k, i)."""
    n = x.shape[0]
    k = np.arange(n - 1)
    rows = _x_columns(k)  # row index (k, i) = 14 k + i, the same layout as x's columns
    sigma = np.full((n - 1, 1), _n_columns(n) - 1)
    blocks = [  # (coefficients (K, 14, width), columns (K, width)) of the terms of z*'s side
        (-disc.A, _x_columns(k)),
        (-disc.Bm, _u_columns(k, n)),
        (-disc.Bp, _u_columns(k + 1, n)),
        (-disc.S[..., None], sigma),
    ]
    data, r_idx, c_idx = [np.ones(rows.size)], [rows.ravel()], [_x_columns(k + 1).ravel()]
    for values, cols in blocks:
        data.append(values.ravel())
        r_idx.append(np.repeat(rows.ravel(), cols.shape[1]))
        c_idx.append(np.broadcast_to(cols[:, None, :], values.shape).ravel())
    shape = ((n - 1) * N_X, _n_columns(n))
    entries = (np.concatenate(data), (np.concatenate(r_idx), np.concatenate(c_idx)))
    return sp.csr_array(sp.coo_array(entries, shape=shape))


def _fixed_rows(n: int, fix_roll: bool) -> sp.csr_array:
    """``Delta x_0 = 0`` and the fixed terminal columns: one unit row each."""
    cols = np.concatenate(
        [np.arange(N_X), (n - 1) * N_X + np.array(fixed_terminal_columns(fix_roll))]
    )
    return _unit_rows(cols, n)


def _n_columns(n: int) -> int:
    """Columns of the stacked change ``(x (n, 14), u (n, 3), sigma)``."""
    return n * (N_X + N_U) + 1


def _unit_rows(cols: np.ndarray, n: int) -> sp.csr_array:
    shape = (cols.size, _n_columns(n))
    return sp.csr_array((np.ones(cols.size), (np.arange(cols.size), cols)), shape=shape)


def _active_rows(
    instance: PDGInstance, z: Trajectory, tight_tol: float
) -> tuple[sp.csr_array, np.ndarray]:
    """Gradients of the rows tight at ``z`` with respect to their node's ``(x_k, u_k)``.

    Central differences of :func:`~scpformer.problems.pdg6dof.constraints.constraint_values`,
    one per variable and all nodes at once (a row depends on its own node only). Rows whose
    gradient vanishes (a row of fixed states, or a norm at zero) are left out. Returns the
    rows and the (names, N) mask of the rows they hold.
    """
    n = z.x.shape[0]
    values = con.constraint_values(instance, z.x, z.u)  # (names, N)
    tight = values >= -tight_tol
    scale_x, scale_u, _ = trust_region_scales(instance)
    steps = 1e-6 * np.concatenate([scale_x, scale_u])  # (17,)
    shifts = np.concatenate([np.diag(steps), -np.diag(steps)])  # (34, 17): +h_j, then -h_j
    points = np.concatenate([z.x, z.u], axis=1)[None] + shifts[:, None, :]  # (34, N, 17)
    flat = points.reshape(-1, N_X + N_U)
    shifted = con.constraint_values(instance, flat[:, :N_X], flat[:, N_X:])
    plus, minus = shifted.reshape(len(values), 2, N_X + N_U, n).transpose(1, 0, 3, 2)
    grads = (plus - minus) / (2.0 * steps)  # (names, N, 17)
    grads[:, 0, :N_X] = 0.0  # x_0 is fixed
    keep = tight & (np.abs(grads).max(axis=-1) > 1e-9)
    _, nodes = np.nonzero(keep)
    g = grads[keep]  # (rows, 17)
    cols = np.hstack([_x_columns(nodes), _u_columns(nodes, n)])
    shape = (nodes.size, _n_columns(n))
    entries = (g.ravel(), (np.repeat(np.arange(nodes.size), N_X + N_U), cols.ravel()))
    return sp.csr_array(sp.coo_array(entries, shape=shape)), keep


def _metric(instance: PDGInstance, n: int) -> np.ndarray:
    """``s^2`` of the stacked variables: the trust-region scales (the subproblem's metric)."""
    scale_x, scale_u, scale_sigma = trust_region_scales(instance)
    return np.concatenate([np.tile(scale_x, n), np.tile(scale_u, n), [scale_sigma]]) ** 2


def _factorized(C: sp.csc_array, s2: np.ndarray) -> Callable[[np.ndarray], np.ndarray | None]:
    """A solver of ``(C D C^T) y = r``, ``D = diag(s2)``, whose last column of ``C`` is the
    final time's.

    That column touches every dynamics row, so ``C D C^T`` is dense; it is the sparse,
    block-tridiagonal ``M0`` of the other columns plus the rank-one ``s2_sigma c c^T``, solved
    by the Sherman-Morrison formula with one sparse LU of ``M0``. Dependent rows (a held row
    that the dynamics and boundary rows already fix) make ``M0`` singular; a relative ridge
    of 1e-12 keeps it factorable.
    """
    C0, c = C[:, :-1], C[:, [-1]].toarray().ravel()
    M0 = (C0 @ sp.diags_array(s2[:-1]) @ C0.T).tocsc()
    ridge = 1e-12 * max(float(M0.diagonal().max()), 1.0)
    try:
        lu = spla.splu(M0 + ridge * sp.eye_array(M0.shape[0], format="csc"))
    except RuntimeError:
        return lambda r: None
    w = lu.solve(c)
    denominator = 1.0 + s2[-1] * float(c @ w)

    def solve(r: np.ndarray) -> np.ndarray | None:
        y0 = lu.solve(r)
        y = y0 - w * (s2[-1] * float(c @ y0) / denominator)
        return y if np.isfinite(y).all() else None

    return solve
