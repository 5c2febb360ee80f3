"""Uncertainty models of the chance-constrained rendezvous and the covariance history (Eq. 14).

Robust ART paper (``robust-art-chance-constrained.txt``), Section 4 and Table 2.

Notation
--------
* ``x`` (N, 6): nominal (mean) scaled ROE ``a_c * delta_alpha`` [m], the solver state of
  :mod:`scpformer.dynamics.roe`; ``X`` (N, 6, 6): its error covariance [m^2].
* ``u`` (N, 3): impulsive delta-v in RTN [m/s], ``u = Delta v_rtn``; ``U`` (N, 3, 3) [m^2/s^2].
* ``stm`` (K, 6, 6): ``Phi(t_{i+1}, t_i)``; ``B`` (N, 6, 3): control input matrix [s];
  ``psi`` (N, 6, 6): ``Psi(t_i)``, scaled ROE -> RTN.
* ``rho = |D Psi x|``: relative range [m], ``D = [I_3, 0_3]``.

Models (Table 2 values are the defaults)
----------------------------------------
* Navigation, ARTMS-like (Eqs. 10-11): ``X_nav = rho^2 diag(s(rho))^2`` in scaled ROE, i.e.
  one standard deviation of ``a_c delta_alpha_j`` is ``rho * s_j``, with ``s`` interpolated
  linearly in range between ``s_2`` (``rho <= rho_2``) and ``s_1`` (``rho >= rho_1``).
  The paper prints ``X_nav = (rho / a^2) s s^T``. Read literally it is dimensionally
  inconsistent ([m] instead of [m^2] with ``s`` in [m]), rank one (not a covariance a filter
  can report), and with ``a = 6738 km`` either negligible (1e-15 m^2) or scaling with the
  square root of range. The reading here is ``X_nav = (rho/a)^2 diag(s)^2`` in dimensionless
  ROE: each ``s_j`` is an angular accuracy (2e-5 to 4e-3 rad, the along-track range being
  the weakly observable direction of angles-only navigation), so errors grow linearly with
  range as they do for a bearings-only sensor, and the uncertainty ellipses are
  visible at the scale of Fig. 7.
  Eq. 11 assigns ``s_2`` at ``rho = rho_1`` exactly; the interpolation is used there instead
  so that ``s`` is continuous.
* Actuation, Gates model (Eqs. 12-13): in the burn frame ``{e1 = Delta v / |Delta v|, e2, e3}``
  ``V = diag(sr^2 + dv^2 ss^2, sa^2 + dv^2 sp^2, sa^2 + dv^2 sp^2)`` and ``U = R V R^T``.
  Because ``V_22 = V_33``, ``U = V_22 I + (V_11 - V_22) e1 e1^T`` for any choice of ``e2, e3``,
  which is what is computed (vectorized, no rotation matrices). A zero burn has no direction;
  ``e1`` is then taken radial (this only matters when ``sigma_r != sigma_a``; with Table 2
  ``U = sigma_a^2 I`` at ``Delta v = 0``).
* Process noise: constant ``Q_roe`` [m^2] in scaled ROE, added at every node.
* Covariance history (Eq. 14): ``X_i = X_nav(x_i) + B_i U(u_i) B_i^T + Q`` (the state
  covariance right after the impulse at ``t_i``, a function of ``(x_i, u_i)`` alone, since a
  new navigation fix is assumed at every node) and ``Phi X_i Phi^T`` its propagation, to
  ``t_{i+1}`` or to the minimum-separation instant ``t*`` of a free-drift arc.
* Chance-constraint margin (Eq. 16): ``beta = q(Delta) |X^(1/2) a|_2`` with
  ``q(Delta) = Phi_N^{-1}(1 - Delta)``, the ONE-SIDED upper quantile (percent point function)
  of the standard normal, because the linearized constraint ``a^T x`` is a scalar Gaussian
  that may only err on one side: ``q(1e-3) = 3.0902`` (Table 2's 3.09; a two-sided reading
  would give 3.29).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import norm

from scpformer.validation import check_finite, check_int, check_positive

__all__ = [
    "CovarianceHistory",
    "GatesModel",
    "NavigationModel",
    "ProcessNoise",
    "UncertaintyModel",
    "burn_frame",
    "chance_margin",
    "check_covariance",
    "confidence_quantile",
    "covariance_history",
    "gates_covariance",
    "navigation_covariance",
    "navigation_scale",
    "propagate_covariance",
    "relative_range",
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

S1_TABLE2 = (4e-5, 4e-3, 4e-5, 2e-5, 2e-5, 4e-5)
S2_TABLE2 = (1e-4, 4e-3, 4e-5, 2e-3, 2e-3, 2e-3)
Q_TABLE2 = tuple(tuple(1e-6 if r == c else 0.0 for c in range(6)) for r in range(6))
_SYM_RTOL = 1e-9  # relative asymmetry tolerated in a covariance (roundoff of Phi X Phi^T)
_PSD_RTOL = 1e-12  # relative negative eigenvalue tolerated in a semi-definite covariance


# ----------------------------------------------------------------------------------------
# validation
# ----------------------------------------------------------------------------------------
def check_covariance(name: str, X: ArrayLike, *, definite: bool = True) -> FloatArray:
    """Return ``X`` as a float array after checking it is a (batch of) covariance matrices.

    Parameters
    ----------
    name
        Field name used in error messages.
    X
        Shape ``(..., n, n)``.
    definite
        Require positive definiteness (default); otherwise positive semi-definiteness, up to
        a relative roundoff of ``1e-12`` of the largest eigenvalue.

    Raises
    ------
    ValueError
        Naming ``name`` when ``X`` is not square, not finite, not symmetric, or not positive
        (semi-)definite.
    """
    X = check_finite(name, X)
    if X.ndim < 2 or X.shape[-1] != X.shape[-2]:
        raise ValueError(f"{name} must have shape (..., n, n), got {X.shape}")
    scale = max(float(np.max(np.abs(X), initial=0.0)), np.finfo(float).tiny)
    if np.max(np.abs(X - np.swapaxes(X, -1, -2)), initial=0.0) > _SYM_RTOL * scale:
        raise ValueError(f"{name} must be symmetric")
    eig = np.linalg.eigvalsh(X)
    low, high = float(np.min(eig)), float(np.max(np.abs(eig), initial=0.0))
    if definite and low <= 0.0:
        raise ValueError(f"{name} must be positive definite, smallest eigenvalue is {low:.3g}")
    if not definite and low < -_PSD_RTOL * high:
        raise ValueError(f"{name} must be positive semi-definite, smallest eigenvalue {low:.3g}")
    return X


def _check_shape(name: str, value: ArrayLike, shape: tuple[int | None, ...]) -> FloatArray:
    """Finite float array whose shape matches ``shape`` (``None`` matches any size)."""
    arr = check_finite(name, value)
    same = arr.ndim == len(shape)
    if not (same and all(s in (None, a) for s, a in zip(shape, arr.shape, strict=True))):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {want}, got {arr.shape}")
    return arr


def _symmetrize(X: FloatArray) -> FloatArray:
    return 0.5 * (X + np.swapaxes(X, -1, -2))


# ----------------------------------------------------------------------------------------
# numeric core: plain arrays, vectorized over any leading (node) axes
# ----------------------------------------------------------------------------------------
def navigation_scale(
    rho: ArrayLike, s1: ArrayLike, s2: ArrayLike, rho1: float, rho2: float
) -> FloatArray:
    """Range-dependent navigation accuracy ``s(rho)`` of Eq. 11, shape ``(..., 6)``.

    ``s = s_1`` for ``rho >= rho_1``, ``s = s_2`` for ``rho <= rho_2`` and
    ``s = (s_1 (rho - rho_2) + s_2 (rho_1 - rho)) / (rho_1 - rho_2)`` in between.
    """
    t = np.clip((np.asarray(rho, dtype=float) - rho2) / (rho1 - rho2), 0.0, 1.0)[..., None]
    s1, s2 = np.asarray(s1, dtype=float), np.asarray(s2, dtype=float)
    return s2 + t * (s1 - s2)


def navigation_covariance(
    rho: ArrayLike, s1: ArrayLike, s2: ArrayLike, rho1: float, rho2: float
) -> FloatArray:
    """ARTMS-like navigation covariance in scaled ROE, ``rho^2 diag(s(rho))^2`` (Eqs. 10-11).

    See the module docstring for the reading of Eq. 10.

    Returns
    -------
    numpy.ndarray
        ``X_nav`` [m^2], shape ``(..., 6, 6)`` for ``rho`` of shape ``(...)``.
    """
    rho = np.asarray(rho, dtype=float)
    sigma = rho[..., None] * navigation_scale(rho, s1, s2, rho1, rho2)  # (..., 6) [m]
    X = np.zeros((*rho.shape, 6, 6))
    idx = np.arange(6)
    X[..., idx, idx] = sigma**2
    return X


def _burn_direction(dv: FloatArray) -> FloatArray:
    """Unit vector along each impulse, radial for a zero impulse, shape ``(..., 3)``."""
    mag = np.linalg.norm(dv, axis=-1, keepdims=True)
    radial = np.broadcast_to(np.array([1.0, 0.0, 0.0]), dv.shape)
    return np.where(mag > 0.0, dv / np.where(mag > 0.0, mag, 1.0), radial)


def burn_frame(dv: ArrayLike) -> FloatArray:
    """Rotation ``R`` from the burn frame ``{e1, e2, e3}`` of Eq. 13 to RTN, ``(..., 3, 3)``.

    Columns are ``e1 = dv / |dv|`` (radial for a zero impulse), ``e2`` orthogonal to ``e1``
    and to the RTN axis least aligned with it, and ``e3 = e1 x e2``. Any ``e2, e3`` give the
    same ``U`` (Eq. 12 has equal pointing variances); this choice is only for sampling.
    """
    e1 = _burn_direction(check_finite("dv", dv))
    axis = np.eye(3)[np.argmin(np.abs(e1), axis=-1)]
    e2 = np.cross(e1, axis)
    e2 /= np.linalg.norm(e2, axis=-1, keepdims=True)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=-1)


def gates_covariance(
    dv: ArrayLike, sigma_s: float, sigma_p: float, sigma_r: float, sigma_a: float
) -> FloatArray:
    """Covariance of the executed impulse, Gates model (Eqs. 12-13), shape ``(..., 3, 3)``.

    ``U = R V R^T = V_22 I + (V_11 - V_22) e1 e1^T`` with
    ``V_11 = sigma_r^2 + |dv|^2 sigma_s^2`` (magnitude) and
    ``V_22 = V_33 = sigma_a^2 + |dv|^2 sigma_p^2`` (pointing).

    Parameters
    ----------
    dv
        Nominal impulses in RTN [m/s], shape ``(..., 3)``.
    sigma_s, sigma_p, sigma_r, sigma_a
        Proportional magnitude [-], proportional pointing [rad], fixed magnitude [m/s] and
        fixed pointing [m/s] standard deviations.
    """
    dv = np.asarray(dv, dtype=float)
    dv2 = np.sum(dv * dv, axis=-1)[..., None, None]
    v_par = sigma_r**2 + dv2 * sigma_s**2
    v_perp = sigma_a**2 + dv2 * sigma_p**2
    e1 = _burn_direction(dv)
    return v_perp * np.eye(3) + (v_par - v_perp) * (e1[..., :, None] * e1[..., None, :])


def relative_range(x: ArrayLike, psi: ArrayLike) -> FloatArray:
    """Relative range ``rho = |D Psi x|_2`` [m] of scaled ROE ``x`` (..., 6), shape ``(...)``."""
    r = np.einsum("...ij,...j->...i", np.asarray(psi, dtype=float)[..., :3, :], x)
    return np.linalg.norm(r, axis=-1)


def propagate_covariance(X: ArrayLike, stm: ArrayLike) -> FloatArray:
    """Covariance after free drift, ``Phi X Phi^T`` (second line of Eq. 14), broadcast."""
    stm = np.asarray(stm, dtype=float)
    return _symmetrize(stm @ np.asarray(X, dtype=float) @ np.swapaxes(stm, -1, -2))


# ----------------------------------------------------------------------------------------
# configuration dataclasses (Table 2 defaults)
# ----------------------------------------------------------------------------------------
def _nonnegative_tuple(name: str, value: ArrayLike, shape: tuple[int]) -> tuple[float, ...]:
    return tuple(check_finite(name, value, shape=shape, nonnegative=True).tolist())


@dataclass(frozen=True, kw_only=True)
class NavigationModel:
    """ARTMS-like navigation accuracy (Eqs. 10-11, Table 2)."""

    s1: tuple[float, ...] = S1_TABLE2  # s_1 [m/m]: 1-sigma of a*delta_alpha_j per m of range, far
    s2: tuple[float, ...] = S2_TABLE2  # s_2 [m/m]: same, at close range (Table 2 prints [m])
    rho1: float = 10_000.0  # rho_1 [m]: beyond it s = s_1
    rho2: float = 1_000.0  # rho_2 [m]: below it s = s_2

    def __post_init__(self) -> None:
        for name in ("s1", "s2"):
            value = _nonnegative_tuple(name, getattr(self, name), (6,))
            object.__setattr__(self, name, value)
        check_finite("rho2", self.rho2, shape=(), nonnegative=True)
        check_positive("rho1", self.rho1)
        if not self.rho1 > self.rho2:
            raise ValueError(f"rho1 must exceed rho2, got rho1={self.rho1}, rho2={self.rho2}")

    def scale(self, rho: ArrayLike) -> FloatArray:
        """``s(rho)`` of Eq. 11, shape ``(..., 6)``."""
        return navigation_scale(rho, self.s1, self.s2, self.rho1, self.rho2)

    def covariance(self, rho: ArrayLike) -> FloatArray:
        """``X_nav(rho)`` [m^2] in scaled ROE (Eq. 10), shape ``(..., 6, 6)``."""
        rho = check_finite("rho", rho, nonnegative=True)
        return navigation_covariance(rho, self.s1, self.s2, self.rho1, self.rho2)


@dataclass(frozen=True, kw_only=True)
class GatesModel:
    """Gates (1963) execution-error model of an impulse (Eqs. 12-13, Table 2)."""

    sigma_s: float = 2e-3  # sigma_s [-]: magnitude error proportional to |dv|
    sigma_p: float = 3e-4  # sigma_p [rad]: pointing error proportional to |dv|
    sigma_r: float = 3e-4  # sigma_r [m/s]: fixed magnitude error
    sigma_a: float = 3e-4  # sigma_a [m/s]: fixed pointing error

    def __post_init__(self) -> None:
        for name in ("sigma_s", "sigma_p", "sigma_r", "sigma_a"):
            value = float(check_finite(name, getattr(self, name), shape=(), nonnegative=True))
            object.__setattr__(self, name, value)

    def covariance(self, dv: ArrayLike) -> FloatArray:
        """``U(dv)`` [m^2/s^2], shape ``(..., 3, 3)`` (Eq. 13)."""
        dv = check_finite("dv", dv)
        return gates_covariance(dv, self.sigma_s, self.sigma_p, self.sigma_r, self.sigma_a)

    def sample(self, dv: ArrayLike, rng: np.random.Generator, n: int) -> FloatArray:
        """``n`` draws of the execution error of each impulse in RTN, shape ``(n, ..., 3)``.

        Drawn in the burn frame as Eq. 12 states it (independent magnitude and two pointing
        errors) and rotated to RTN with :func:`burn_frame`.
        """
        dv = check_finite("dv", dv)
        dv2 = np.sum(dv * dv, axis=-1)
        sd = np.stack(
            [
                np.sqrt(self.sigma_r**2 + dv2 * self.sigma_s**2),
                np.sqrt(self.sigma_a**2 + dv2 * self.sigma_p**2),
                np.sqrt(self.sigma_a**2 + dv2 * self.sigma_p**2),
            ],
            axis=-1,
        )  # (..., 3)
        local = rng.standard_normal((n, *dv.shape)) * sd
        return np.einsum("...ij,n...j->n...i", burn_frame(dv), local)


@dataclass(frozen=True, kw_only=True)
class ProcessNoise:
    """Constant process noise of the unmodeled dynamics in scaled ROE (Table 2)."""

    Q_roe: tuple[tuple[float, ...], ...] = Q_TABLE2  # Q_roe [m^2], symmetric positive definite

    def __post_init__(self) -> None:
        Q = check_covariance("Q_roe", _check_shape("Q_roe", self.Q_roe, (6, 6)))
        object.__setattr__(self, "Q_roe", tuple(tuple(row) for row in Q.tolist()))

    @property
    def matrix(self) -> FloatArray:
        """``Q_roe`` as a (6, 6) array."""
        return np.array(self.Q_roe)


def confidence_quantile(delta: float) -> float:
    """``q(Delta) = Phi_N^{-1}(1 - Delta)``, one-sided standard-normal quantile (Eq. 16).

    ``q(1e-3) = 3.0902`` (Table 2: 3.09). Computed as the inverse survival function for
    accuracy at small ``Delta``.

    Raises
    ------
    ValueError
        If ``Delta`` is not a finite number in the open interval (0, 1).
    """
    delta = float(check_finite("delta", delta, shape=()))
    if not 0.0 < delta < 1.0:
        raise ValueError(f"delta must lie in the open interval (0, 1), got {delta}")
    return float(norm.isf(delta))


@dataclass(frozen=True, kw_only=True)
class UncertaintyModel:
    """All uncertainty of the chance-constrained problem: Table 2 by default.

    ``fix_every`` is the interval ``K`` of the navigation fixes, in nodes of the problem: a fix
    at the nodes ``0, K, 2K, ...`` (the first node is always one). The paper's Eq. 14 assumes
    a fix before every maneuver (``K = 1``, the default); a closed loop that navigates and
    re-plans every ``K`` nodes flies the plan open loop in between, and its dispersion grows
    from the last fix (:func:`covariance_history`).
    """

    navigation: NavigationModel = field(default_factory=NavigationModel)
    actuation: GatesModel = field(default_factory=GatesModel)
    process_noise: ProcessNoise = field(default_factory=ProcessNoise)
    delta: float = 1e-3  # Delta_i: allowed probability of violating a safety constraint
    fix_every: int = 1  # K: navigation fixes at nodes 0, K, 2K, ... (1: Eq. 14, every node)

    def __post_init__(self) -> None:
        confidence_quantile(self.delta)
        object.__setattr__(self, "fix_every", check_int("fix_every", self.fix_every, least=1))

    def fixes(self, n_nodes: int) -> BoolArray:
        """Whether node ``i = 0 .. n_nodes-1`` has a navigation fix, (n_nodes,) bool."""
        return np.arange(n_nodes) % self.fix_every == 0

    @property
    def q(self) -> float:
        """``q(Delta)`` of Eq. 16 (3.09 for the default ``Delta = 1e-3``)."""
        return confidence_quantile(self.delta)


# ----------------------------------------------------------------------------------------
# covariance history and chance-constraint margin
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CovarianceHistory:
    """Covariance history of Eq. 14 along a nominal trajectory."""

    X: FloatArray  # (N, 6, 6) [m^2]: X(t_i) after the impulse and navigation update
    X_next: FloatArray  # (K, 6, 6) [m^2]: Phi(t_{i+1}, t_i) X(t_i) Phi^T, before t_{i+1}
    X_nav: FloatArray  # (N, 6, 6): navigation part of X (zero between the fixes)
    X_act: FloatArray  # (N, 6, 6): actuation part B U B^T of X
    rho: FloatArray  # (N,) [m]: relative range used by the navigation model
    X_carry: FloatArray  # (N, 6, 6): Phi X(t_{i-1}) Phi^T carried between fixes (zero at them)


def _check_history_inputs(
    x: ArrayLike, u: ArrayLike, stm: ArrayLike, B: ArrayLike, psi: ArrayLike
) -> tuple[FloatArray, ...]:
    x = _check_shape("x", x, (None, 6))
    n = x.shape[0]
    u = _check_shape("u", u, (n, 3))
    B = _check_shape("B", B, (n, 6, 3))
    psi = _check_shape("psi", psi, (n, 6, 6))
    stm = _check_shape("stm", stm, (None, 6, 6))
    if stm.shape[0] not in (n - 1, n):
        raise ValueError(f"stm must hold N-1 or N = {n} matrices, got {stm.shape[0]}")
    return x, u, stm, B, psi


def covariance_history(
    x: ArrayLike,
    u: ArrayLike,
    stm: ArrayLike,
    B: ArrayLike,
    psi: ArrayLike,
    model: UncertaintyModel | None = None,
) -> CovarianceHistory:
    """Covariance history of Eq. 14 from a nominal ``(x, u)`` history, vectorized over nodes.

    ``X(t_i) = X_nav(x_i) + B_i U(u_i) B_i^T + Q`` and ``X(t_{i+1}^-) = Phi_i X(t_i) Phi_i^T``.

    With navigation fixes only every ``K = model.fix_every`` nodes, the plan is flown open
    loop between them and the error of the state after the maneuver at a node ``i`` without
    a fix is the previous one carried by the dynamics, plus the maneuver's execution error and
    the process noise of the node:

        X(t_i) = Phi_{i-1} X(t_{i-1}) Phi_{i-1}^T + B_i U(u_i) B_i^T + Q,    i mod K != 0,

    and Eq. 14 at the fixes (``CovarianceHistory.X_carry`` holds the carried part, zero at
    the fixes, ``X_nav`` is zero between them). This is the first-order covariance of the
    truth flight of :func:`scpformer.guidance.rendezvous_mpc.fly_truth` (process noise, then
    the fix, then the burn, at each node). The recursion runs over the nodes (``K - 1`` steps
    of a ``(6, 6)`` product per fix interval).

    Parameters
    ----------
    x
        Nominal scaled ROE [m], shape ``(N, 6)``.
    u
        Nominal impulses in RTN [m/s], shape ``(N, 3)`` (zeros where there is no burn).
    stm
        ``Phi(t_{i+1}, t_i)``, shape ``(N-1, 6, 6)`` (or ``(N, 6, 6)``).
    B
        Control input matrices [s], shape ``(N, 6, 3)``.
    psi
        ``Psi(t_i)`` (scaled ROE -> RTN), shape ``(N, 6, 6)``; gives the range of Eq. 10.
    model
        Uncertainty parameters (default: Table 2).

    Raises
    ------
    ValueError
        On wrong shapes or non-finite values, naming the argument.
    """
    model = model or UncertaintyModel()
    x, u, stm, B, psi = _check_history_inputs(x, u, stm, B, psi)
    rho = relative_range(x, psi)  # (N,)
    fixes = model.fixes(x.shape[0])
    X_nav = model.navigation.covariance(rho) * fixes[:, None, None]  # (N, 6, 6)
    X_act = _symmetrize(B @ model.actuation.covariance(u) @ np.swapaxes(B, -1, -2))
    X = X_nav + X_act + model.process_noise.matrix
    X_carry = np.zeros_like(X)
    for i in np.flatnonzero(~fixes):  # ascending: node i - 1 is final when node i is reached
        X_carry[i] = propagate_covariance(X[i - 1], stm[i - 1])
        X[i] = X[i] + X_carry[i]
    X_next = propagate_covariance(X[: stm.shape[0]], stm)
    return CovarianceHistory(X=X, X_next=X_next, X_nav=X_nav, X_act=X_act, rho=rho,
                             X_carry=X_carry)  # fmt: skip


def chance_margin(X: ArrayLike, a: ArrayLike, delta: float = 1e-3) -> FloatArray:
    """Chance-constraint margin ``beta = q(Delta) |X^(1/2) a|_2`` (Eq. 16), vectorized.

    For the symmetric square root, ``|X^(1/2) a|_2 = sqrt(a^T X a)``, which is computed
    (no matrix square root). ``beta`` is the one-sided ``1 - Delta`` quantile of ``a^T e``
    for a Gaussian error ``e ~ N(0, X)``; it vanishes for ``X = 0`` (deterministic case).

    Parameters
    ----------
    X
        Covariances, shape ``(..., n, n)``, symmetric positive semi-definite.
    a
        Constraint gradients ``a_ps``, shape ``(..., n)`` (broadcast against ``X``).
    delta
        Allowed violation probability ``Delta`` in (0, 1).

    Returns
    -------
    numpy.ndarray
        ``beta >= 0`` with the broadcast batch shape.
    """
    q = confidence_quantile(delta)
    X = check_covariance("X", X, definite=False)
    a = check_finite("a", a)
    if a.ndim == 0 or a.shape[-1] != X.shape[-1]:
        raise ValueError(f"a must have shape (..., {X.shape[-1]}), got {a.shape}")
    var = np.einsum("...i,...ij,...j->...", a, X, a)
    return q * np.sqrt(np.maximum(var, 0.0))
