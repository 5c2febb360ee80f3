"""First-order-hold discretization with time dilation, vectorized over all intervals.

Notation
--------
tau in [0, 1]     normalized time, t = sigma tau, nodes tau_k = k / (N - 1)
sigma             time dilation = final time t_f (free-final-time problems)
u(tau)            first-order hold: lambda_m(tau) u_k + lambda_p(tau) u_{k+1}

On each interval the nonlinear flow ``x_{k+1} = F(x_k, u_k, u_{k+1}, sigma)`` is linearized as

    x_{k+1} ~ A_k x_k + Bm_k u_k + Bp_k u_{k+1} + S_k sigma + z_k                 (Eq. 10)

(Szmuk & Acikmese 2018; Malyuta et al. 2022, Sec. 4.2). The sensitivities are integrated in
their forward form, which needs no inverse of the transition matrix:

    d/dtau x  = sigma f(x, u)
    d/dtau P  = sigma A(tau) P + [0 | sigma B lambda_m | sigma B lambda_p | f],  P = [Phi|Bm|Bp|S]

with ``P(tau_k) = [I | 0 | 0 | 0]``. All N - 1 intervals are integrated together with a
fixed-step RK4 of ``n_sub`` steps each, so one call costs ``4 n_sub`` batched evaluations of the
dynamics and Jacobians.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
DynamicsFn = Callable[[Array, Array], Array]
LinearizeFn = Callable[[Array, Array], tuple[Array, Array, Array]]


@dataclass(frozen=True)
class FOHDiscretization:
    """Linearized discrete dynamics about a reference trajectory (all arrays per interval)."""

    A: Array  # (K, n, n) state transition Phi(tau_{k+1}, tau_k)
    Bm: Array  # (K, n, m) sensitivity to u_k
    Bp: Array  # (K, n, m) sensitivity to u_{k+1}
    S: Array  # (K, n) sensitivity to sigma
    z: Array  # (K, n) affine term
    x_next: Array  # (K, n) nonlinear flow F(x_k, u_k, u_{k+1}, sigma)

    def defects(self, x: Array) -> Array:
        """Dynamics defects ``x_{k+1} - F(x_k, u_k, u_{k+1}, sigma)`` (K, n) of the reference."""
        return x[1:] - self.x_next


def foh_discretize(
    linearize: LinearizeFn,
    x: Array,
    u: Array,
    sigma: float,
    n_sub: int,
) -> FOHDiscretization:
    """Discretize about ``(x, u, sigma)`` with first-order hold (Eq. 10 of the T-SCvx paper).

    Parameters
    ----------
    linearize
        Vectorized ``(f, df/dx, df/du)`` of shapes (K, n), (K, n, n), (K, n, m) in one call
        (the dynamics and their Jacobians share most of their work).
    x, u
        Reference states (N, n) and controls (N, m) at the nodes.
    sigma
        Reference time dilation (final time).
    n_sub
        RK4 steps per interval.
    """
    n_nodes, n = x.shape
    m = u.shape[1]
    k = n_nodes - 1
    u_m, u_p = u[:-1], u[1:]
    state = x[:-1].copy()
    sens = np.zeros((k, n, n + 2 * m + 1))
    sens[:, :, :n] = np.eye(n)

    def rates(lam_p: float, state: Array, sens: Array) -> tuple[Array, Array]:
        lam_m = 1.0 - lam_p
        uu = lam_m * u_m + lam_p * u_p
        f, A, B = linearize(state, uu)
        dsens = sigma * (A @ sens)
        dsens[:, :, n : n + m] += sigma * lam_m * B
        dsens[:, :, n + m : n + 2 * m] += sigma * lam_p * B
        dsens[:, :, -1] += f
        return sigma * f, dsens

    state, sens = _rk4(rates, (state, sens), n_sub)
    A = sens[:, :, :n]
    Bm = sens[:, :, n : n + m]
    Bp = sens[:, :, n + m : n + 2 * m]
    S = sens[:, :, -1]
    affine = (
        np.einsum("kij,kj->ki", A, x[:-1])
        + np.einsum("kij,kj->ki", Bm, u_m)
        + np.einsum("kij,kj->ki", Bp, u_p)
        + S * sigma
    )
    return FOHDiscretization(A=A, Bm=Bm, Bp=Bp, S=S, z=state - affine, x_next=state)


def foh_flow(dynamics: DynamicsFn, x: Array, u: Array, sigma: float, n_sub: int) -> Array:
    """The nonlinear flow ``F(x_k, u_k, u_{k+1}, sigma)`` (K, n) alone: the ``x_next`` of
    :func:`foh_discretize` (the same RK4 steps) without the sensitivities, at a quarter of
    its cost."""
    u_m, u_p = u[:-1], u[1:]

    def rates(lam_p: float, state: Array) -> tuple[Array]:
        return (sigma * dynamics(state, (1.0 - lam_p) * u_m + lam_p * u_p),)

    return _rk4(rates, (x[:-1].copy(),), n_sub)[0]


def _rk4(
    rates: Callable[..., tuple[Array, ...]], y: tuple[Array, ...], n_sub: int
) -> tuple[Array, ...]:
    """``n_sub`` classical RK4 steps over ``tau`` in [0, 1] of every interval at once.

    ``y`` is a tuple of arrays integrated together; ``rates(lam_p, *y)`` returns their
    derivatives with respect to ``tau / dtau`` at the FOH weight ``lam_p`` of ``u_{k+1}``.
    The step is ``h = 1 / (K n_sub)`` in normalized time, ``K`` the number of intervals (the
    leading axis of every array).
    """
    h = 1.0 / (y[0].shape[0] * n_sub)

    def moved(base: tuple[Array, ...], slope: tuple[Array, ...], a: float) -> tuple[Array, ...]:
        return tuple(b + a * s for b, s in zip(base, slope, strict=True))

    for step in range(n_sub):
        lam0 = step / n_sub
        half = lam0 + 0.5 / n_sub
        k1 = rates(lam0, *y)
        k2 = rates(half, *moved(y, k1, 0.5 * h))
        k3 = rates(half, *moved(y, k2, 0.5 * h))
        k4 = rates((step + 1) / n_sub, *moved(y, k3, h))
        y = tuple(
            b + (h / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
            for b, a1, a2, a3, a4 in zip(y, k1, k2, k3, k4, strict=True)
        )
    return y
