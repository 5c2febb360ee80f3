"""The rendezvous constraints: keep-out linearization (Eqs. 14-16), cone (Eq. 13), tight
flags, and the reward- and constraint-to-go of the ART paper (Eqs. 4-5, 20-21)."""

from __future__ import annotations

import math

import numpy as np

from scpformer.problems.rendezvous.scenario import RendezvousScenario

CTG_TOL = 1e-6  # constraint-to-go: a node counts as violating when |E_koz dr| < 1 - CTG_TOL


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
    nk, kc, n = scenario.n_keep_out, scenario.cone_start, scenario.n_nodes
    return [("keep_out", k) for k in range(nk)] + [("approach_cone", k) for k in range(kc, n)]


def tight_flags(rtn: np.ndarray, scenario: RendezvousScenario, tol: float) -> np.ndarray:
    """Rows of :func:`constraint_index` whose slack is at most ``tol`` ([-] keep-out, [m] cone).

    ``rtn`` holds the relative states of all nodes, (N+1, >=3).
    """
    nk, kc, n = scenario.n_keep_out, scenario.cone_start, scenario.n_nodes
    koz = keep_out_slack(rtn[:nk], scenario) <= tol
    return np.concatenate([koz, cone_slack(rtn[kc:n], scenario) <= tol])


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
    nk = scenario.n_keep_out  # 0 once the waypoint is passed
    flags[:nk] = keep_out_slack(rtn[:nk], scenario) < -tol
    return np.cumsum(flags[::-1])[::-1].copy()
