"""Absolute orbit mechanics: Kepler's equation, orbital elements, inertial states, J2 drift.

Conventions
-----------
* Classical orbital elements ``oe = (a, e, i, raan, argp, M)``: semi-major axis ``a`` in
  metres, eccentricity ``e``, inclination ``i``, right ascension of the ascending node
  ``raan``, argument of periapsis ``argp`` and mean anomaly ``M``; angles in radians.
  Arrays of elements have shape ``(..., 6)``.
* Quasi-nonsingular elements ``qns = (a, u, ex, ey, i, raan)`` with ``u = argp + M`` the
  mean argument of latitude and ``(ex, ey) = e (cos argp, sin argp)`` (D'Amico 2010,
  Sec. 2.1; Vallado 2013).
* Inertial (ECI) position in metres and velocity in m/s, shape ``(..., 3)``.
* RTN frame of a spacecraft with inertial state ``(r, v)``: ``R = r/|r|``,
  ``N = (r x v)/|r x v|``, ``T = N x R``. Its angular velocity is taken as the osculating
  Keplerian one, ``omega = (r x v)/|r|^2`` (exact for two-body motion; under J2 it omits the
  out-of-plane frame rate ``r a_N / h``, about 1.6e-6 rad/s in low Earth orbit). This
  makes every map between RTN and inertial states a pure function of the two inertial
  states, and the maps in :mod:`scpformer.dynamics.roe` exact inverses of each other.

Physical constants follow the specification of the project (EGM-like values).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scpformer.dynamics.quaternion import cross
from scpformer.validation import shown

__all__ = [
    "J2",
    "MU_EARTH",
    "R_EARTH",
    "OrbitalElements",
    "accel_two_body_j2",
    "eccentric_to_mean",
    "eccentric_to_true",
    "eci_to_oe",
    "eci_to_rtn",
    "j2_secular_rates",
    "mean_motion",
    "mean_to_true",
    "oe_to_eci",
    "oe_to_qns",
    "orbital_period",
    "propagate_kepler",
    "propagate_mean_j2",
    "propagate_mean_qns",
    "qns_to_oe",
    "rtn_dcm",
    "rtn_to_eci",
    "solve_kepler",
    "true_to_eccentric",
    "true_to_mean",
    "validate_oe",
    "wrap_angle",
    "wrap_to_pi",
]

MU_EARTH: float = 3.986004418e14
"""Earth gravitational parameter [m^3/s^2]."""
R_EARTH: float = 6378.1363e3
"""Earth equatorial radius [m]."""
J2: float = 1.082626683e-3
"""Earth second zonal harmonic [-]."""

_FIELDS = ("a", "e", "i", "raan", "argp", "M")
FloatArray = NDArray[np.float64]


# ----------------------------------------------------------------------------------------
# validation helpers
# ----------------------------------------------------------------------------------------
def _as_float_array(x: ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float array ({exc})") from exc
    return arr


def _check_finite(arr: FloatArray, name: str) -> None:
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")


def _check_last_dim(arr: FloatArray, size: int, name: str) -> None:
    if arr.ndim == 0 or arr.shape[-1] != size:
        raise ValueError(f"{name}: expected shape (..., {size}), got {arr.shape}")


def validate_oe(oe: ArrayLike | OrbitalElements, name: str = "oe") -> FloatArray:
    """Return classical orbital elements as a float array of shape ``(..., 6)``.

    Parameters
    ----------
    oe
        ``(a, e, i, raan, argp, M)`` (or an :class:`OrbitalElements`), shape ``(..., 6)``.
    name
        Name of the argument, used in error messages.

    Raises
    ------
    ValueError
        If the shape is wrong, a value is NaN/inf, ``a < R_EARTH``, ``e < 0``, ``e >= 1``
        or ``i`` outside ``[0, pi]``. The message names the offending field.
    """
    if isinstance(oe, OrbitalElements):
        return oe.to_array()
    arr = _as_float_array(oe, name)
    _check_last_dim(arr, 6, name)
    a, e, inc = arr[..., 0], arr[..., 1], arr[..., 2]
    if (
        np.isfinite(arr).all()
        and ((a >= R_EARTH) & (e >= 0.0) & (e < 1.0) & (inc >= 0.0) & (inc <= np.pi)).all()
    ):
        return arr  # the common case in one pass; a failure is named below
    for k, field in enumerate(_FIELDS):
        if not np.all(np.isfinite(arr[..., k])):
            raise ValueError(f"{name}.{field}: contains NaN or inf")
    if np.any(a < R_EARTH):
        raise ValueError(
            f"{name}.a: semi-major axis {np.min(a):.6g} m is below the Earth radius {R_EARTH:.6g} m"
        )
    if np.any(e < 0.0):
        raise ValueError(f"{name}.e: eccentricity {np.min(e):.6g} is negative")
    if np.any(e >= 1.0):
        raise ValueError(f"{name}.e: eccentricity {np.max(e):.6g} >= 1 (orbit not closed)")
    if np.any((inc < 0.0) | (inc > np.pi)):
        raise ValueError(f"{name}.i: inclination must lie in [0, pi] rad")
    return arr


def wrap_angle(x: ArrayLike) -> FloatArray:
    """Wrap angles to ``[0, 2 pi)``."""
    return np.mod(np.asarray(x, dtype=float), 2.0 * np.pi)


def wrap_to_pi(x: ArrayLike) -> FloatArray:
    """Wrap angles to ``[-pi, pi)``."""
    return np.mod(np.asarray(x, dtype=float) + np.pi, 2.0 * np.pi) - np.pi


# ----------------------------------------------------------------------------------------
# anomalies
# ----------------------------------------------------------------------------------------
def solve_kepler(M: ArrayLike, e: ArrayLike, tol: float = 1e-14, max_iter: int = 50) -> FloatArray:
    """Solve Kepler's equation ``M = E - e sin E`` for the eccentric anomaly (vectorized).

    Newton iteration started from Danby's guess ``E0 = M + 0.85 e sign(sin M)`` (Vallado
    2013, Alg. 2; Danby 1988). Converges for all ``0 <= e < 1``.

    Parameters
    ----------
    M
        Mean anomaly [rad], any shape (broadcast with ``e``).
    e
        Eccentricity, ``0 <= e < 1``.
    tol
        Absolute tolerance on the Newton step [rad].
    max_iter
        Maximum number of Newton iterations.

    Returns
    -------
    numpy.ndarray
        Eccentric anomaly ``E`` [rad], with the same 2 pi branch as ``M`` (``E - M`` is
        within ``[-e, e]``).
    """
    M = _as_float_array(M, "M")
    e = _as_float_array(e, "e")
    _check_finite(M, "M")
    _check_finite(e, "e")
    if np.any((e < 0.0) | (e >= 1.0)):
        raise ValueError("e: eccentricity must satisfy 0 <= e < 1")
    M, e = np.broadcast_arrays(M, e)
    Mw = wrap_to_pi(M)
    E = Mw + 0.85 * e * np.where(np.sin(Mw) >= 0.0, 1.0, -1.0)
    for _ in range(max_iter):
        f = E - e * np.sin(E) - Mw
        step = f / (1.0 - e * np.cos(E))
        E = E - step
        if np.all(np.abs(step) < tol):
            break
    return E + (M - Mw)


def eccentric_to_true(E: ArrayLike, e: ArrayLike) -> FloatArray:
    """True anomaly from eccentric anomaly, ``tan(f/2) = sqrt((1+e)/(1-e)) tan(E/2)``."""
    E = np.asarray(E, dtype=float)
    e = np.asarray(e, dtype=float)
    f = 2.0 * np.arctan2(np.sqrt(1.0 + e) * np.sin(E / 2), np.sqrt(1.0 - e) * np.cos(E / 2))
    return f


def true_to_eccentric(f: ArrayLike, e: ArrayLike) -> FloatArray:
    """Eccentric anomaly from true anomaly, ``tan(E/2) = sqrt((1-e)/(1+e)) tan(f/2)``."""
    f = np.asarray(f, dtype=float)
    e = np.asarray(e, dtype=float)
    return 2.0 * np.arctan2(np.sqrt(1.0 - e) * np.sin(f / 2), np.sqrt(1.0 + e) * np.cos(f / 2))


def eccentric_to_mean(E: ArrayLike, e: ArrayLike) -> FloatArray:
    """Mean anomaly from eccentric anomaly (Kepler's equation)."""
    E = np.asarray(E, dtype=float)
    return E - np.asarray(e, dtype=float) * np.sin(E)


def true_to_mean(f: ArrayLike, e: ArrayLike) -> FloatArray:
    """Mean anomaly from true anomaly, in ``(-pi, pi]``."""
    return eccentric_to_mean(true_to_eccentric(f, e), e)


def mean_to_true(M: ArrayLike, e: ArrayLike) -> FloatArray:
    """True anomaly from mean anomaly (solves Kepler's equation); same 2 pi branch as ``M``."""
    M = np.asarray(M, dtype=float)
    E = solve_kepler(M, e)
    f = eccentric_to_true(E, e)
    # eccentric_to_true returns (-pi, pi]; restore the branch of E.
    return f + 2.0 * np.pi * np.round((E - f) / (2.0 * np.pi))


# ----------------------------------------------------------------------------------------
# basic orbit quantities
# ----------------------------------------------------------------------------------------
def mean_motion(a: ArrayLike, mu: float = MU_EARTH) -> FloatArray:
    """Keplerian mean motion ``n = sqrt(mu / a^3)`` [rad/s].

    Raises
    ------
    ValueError
        If ``a`` is non-finite or below the Earth radius.
    """
    a = _as_float_array(a, "a")
    _check_finite(a, "a")
    if np.any(a < R_EARTH):
        raise ValueError(f"a: semi-major axis {np.min(a):.6g} m is below the Earth radius")
    return np.sqrt(mu / a**3)


def orbital_period(a: ArrayLike, mu: float = MU_EARTH) -> FloatArray:
    """Keplerian orbital period ``2 pi / n`` [s]."""
    return 2.0 * np.pi / mean_motion(a, mu)


def oe_to_qns(oe: ArrayLike) -> FloatArray:
    """Classical ``(a, e, i, raan, argp, M)`` to quasi-nonsingular ``(a, u, ex, ey, i, raan)``.

    ``u = argp + M`` (wrapped to ``[0, 2 pi)``), ``ex = e cos argp``, ``ey = e sin argp``
    (D'Amico 2010, Eq. 2.2).
    """
    oe = validate_oe(oe)
    a, e, i, raan, argp, M = np.moveaxis(oe, -1, 0)
    return np.stack([a, wrap_angle(argp + M), e * np.cos(argp), e * np.sin(argp), i, raan], axis=-1)


def qns_to_oe(qns: ArrayLike) -> FloatArray:
    """Quasi-nonsingular ``(a, u, ex, ey, i, raan)`` to classical elements.

    For ``e == 0`` the argument of periapsis is set to 0 and ``M = u``.
    """
    qns = _as_float_array(qns, "qns")
    _check_last_dim(qns, 6, "qns")
    _check_finite(qns, "qns")
    a, u, ex, ey, i, raan = np.moveaxis(qns, -1, 0)
    e = np.hypot(ex, ey)
    argp = np.where(e > 0.0, np.arctan2(ey, ex), 0.0)
    oe = np.stack([a, e, i, wrap_angle(raan), wrap_angle(argp), wrap_angle(u - argp)], axis=-1)
    return validate_oe(oe, "qns")


# ----------------------------------------------------------------------------------------
# orbital elements <-> inertial state
# ----------------------------------------------------------------------------------------
def oe_to_eci(oe: ArrayLike, mu: float = MU_EARTH) -> tuple[FloatArray, FloatArray]:
    """Inertial position and velocity from classical orbital elements (vectorized).

    Perifocal state from the eccentric anomaly rotated by ``R3(-raan) R1(-i) R3(-argp)``
    (Vallado 2013, Alg. 10).

    Parameters
    ----------
    oe
        ``(a, e, i, raan, argp, M)``, shape ``(..., 6)``.
    mu
        Gravitational parameter [m^3/s^2].

    Returns
    -------
    r, v
        ECI position [m] and velocity [m/s], each of shape ``(..., 3)``.
    """
    oe = validate_oe(oe)
    a, e, i, raan, argp, M = np.moveaxis(oe, -1, 0)
    E = solve_kepler(M, e)
    cE, sE = np.cos(E), np.sin(E)
    eta = np.sqrt(1.0 - e**2)
    r_mag = a * (1.0 - e * cE)
    n = np.sqrt(mu / a**3)
    xp = a * (cE - e)
    yp = a * eta * sE
    vxp = -n * a**2 / r_mag * sE
    vyp = n * a**2 / r_mag * eta * cE
    cO, sO = np.cos(raan), np.sin(raan)
    cw, sw = np.cos(argp), np.sin(argp)
    ci, si = np.cos(i), np.sin(i)
    # Columns of the perifocal-to-ECI rotation: P (periapsis) and Q (in-plane, +90 deg).
    P = np.stack([cO * cw - sO * sw * ci, sO * cw + cO * sw * ci, sw * si], axis=-1)
    Q = np.stack([-cO * sw - sO * cw * ci, -sO * sw + cO * cw * ci, cw * si], axis=-1)
    r = xp[..., None] * P + yp[..., None] * Q
    v = vxp[..., None] * P + vyp[..., None] * Q
    return r, v


def eci_to_oe(r: ArrayLike, v: ArrayLike, mu: float = MU_EARTH) -> FloatArray:
    """Classical orbital elements from inertial position and velocity (vectorized).

    Angles are computed through the node frame and the eccentricity vector projected on
    it, so the mean argument of latitude ``argp + M`` stays accurate for near-circular
    orbits. For ``e == 0`` the argument of periapsis is 0; for ``i == 0`` the node is the
    ECI x axis (``raan == 0``).

    Parameters
    ----------
    r, v
        ECI position [m] and velocity [m/s], shape ``(..., 3)``.
    mu
        Gravitational parameter [m^3/s^2].

    Returns
    -------
    numpy.ndarray
        ``(a, e, i, raan, argp, M)`` with angles in ``[0, 2 pi)`` (``i`` in ``[0, pi]``),
        shape ``(..., 6)``.

    Raises
    ------
    ValueError
        On wrong shapes, NaN/inf, a rectilinear or unbound (``e >= 1``) orbit, or a
        semi-major axis below the Earth radius.
    """
    r = _as_float_array(r, "r")
    v = _as_float_array(v, "v")
    _check_last_dim(r, 3, "r")
    _check_last_dim(v, 3, "v")
    _check_finite(r, "r")
    _check_finite(v, "v")
    r, v = np.broadcast_arrays(r, v)
    r_mag = np.linalg.norm(r, axis=-1)
    if np.any(r_mag == 0.0):
        raise ValueError("r: zero position vector")
    h = cross(r, v)
    h_mag = np.linalg.norm(h, axis=-1)
    if np.any(h_mag <= 1e-12 * r_mag * np.linalg.norm(v, axis=-1)):
        raise ValueError("v: rectilinear orbit (angular momentum is zero)")
    energy = 0.5 * np.sum(v * v, axis=-1) - mu / r_mag
    if np.any(energy >= 0.0):
        raise ValueError("v: unbound orbit (e >= 1), orbital energy is non-negative")
    a = -mu / (2.0 * energy)
    h_hat = h / h_mag[..., None]
    inc = np.arctan2(np.hypot(h[..., 0], h[..., 1]), h[..., 2])
    node_norm = np.hypot(h[..., 0], h[..., 1])
    equatorial = node_norm <= 1e-14 * h_mag
    raan = np.where(equatorial, 0.0, np.arctan2(h[..., 0], -h[..., 1]))
    p1 = np.stack([np.cos(raan), np.sin(raan), np.zeros_like(raan)], axis=-1)
    p2 = cross(h_hat, p1)
    e_vec = cross(v, h) / mu - r / r_mag[..., None]
    ex = np.sum(e_vec * p1, axis=-1)
    ey = np.sum(e_vec * p2, axis=-1)
    e = np.hypot(ex, ey)
    if np.any(e >= 1.0):
        raise ValueError("v: unbound orbit (e >= 1)")
    argp = np.where(e > 0.0, np.arctan2(ey, ex), 0.0)
    theta = np.arctan2(np.sum(r * p2, axis=-1), np.sum(r * p1, axis=-1))
    M = true_to_mean(theta - argp, e)
    oe = np.stack([a, e, inc, wrap_angle(raan), wrap_angle(argp), wrap_angle(M)], axis=-1)
    return validate_oe(oe, "eci_to_oe(r, v)")


# ----------------------------------------------------------------------------------------
# RTN frame
# ----------------------------------------------------------------------------------------
def rtn_dcm(r: ArrayLike, v: ArrayLike) -> FloatArray:
    """Rotation matrix from ECI to the RTN frame of the state ``(r, v)``.

    Returns an array of shape ``(..., 3, 3)`` whose rows are the unit vectors ``R, T, N``
    expressed in ECI, so that ``x_rtn = C @ x_eci``.
    """
    r = np.asarray(r, dtype=float)
    v = np.asarray(v, dtype=float)
    R = r / np.linalg.norm(r, axis=-1, keepdims=True)
    h = cross(r, v)
    N = h / np.linalg.norm(h, axis=-1, keepdims=True)
    T = cross(N, R)
    return np.stack([R, T, N], axis=-2)


def eci_to_rtn(r_c: ArrayLike, v_c: ArrayLike, r_d: ArrayLike, v_d: ArrayLike) -> FloatArray:
    """Relative state of a deputy in the chief's rotating RTN frame.

    ``rho = C (r_d - r_c)`` and ``rho_dot = C (v_d - v_c) - omega x rho`` with
    ``omega = (0, 0, |r_c x v_c| / |r_c|^2)`` in RTN (osculating Keplerian frame rate, see
    module docstring).

    Returns
    -------
    numpy.ndarray
        ``(dr_R, dr_T, dr_N, dv_R, dv_T, dv_N)`` [m, m/s], shape ``(..., 6)``.
    """
    r_c, v_c, r_d, v_d = np.broadcast_arrays(
        *(np.asarray(x, dtype=float) for x in (r_c, v_c, r_d, v_d))
    )
    C = rtn_dcm(r_c, v_c)
    rho = np.einsum("...ij,...j->...i", C, r_d - r_c)
    drho = np.einsum("...ij,...j->...i", C, v_d - v_c)
    w = np.linalg.norm(cross(r_c, v_c), axis=-1) / np.sum(r_c * r_c, axis=-1)
    # omega x rho with omega = w N: (-w rho_T, w rho_R, 0)
    drho = drho - np.stack([-w * rho[..., 1], w * rho[..., 0], np.zeros_like(w)], axis=-1)
    return np.concatenate([rho, drho], axis=-1)


def rtn_to_eci(r_c: ArrayLike, v_c: ArrayLike, rtn: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Deputy inertial state from the chief inertial state and the relative RTN state.

    Exact inverse of :func:`eci_to_rtn`.

    Returns
    -------
    r_d, v_d
        Deputy ECI position [m] and velocity [m/s], shape ``(..., 3)``.
    """
    rtn = np.asarray(rtn, dtype=float)
    r_c, v_c, rho, drho = np.broadcast_arrays(
        np.asarray(r_c, dtype=float), np.asarray(v_c, dtype=float), rtn[..., :3], rtn[..., 3:]
    )
    C = rtn_dcm(r_c, v_c)
    w = np.linalg.norm(cross(r_c, v_c), axis=-1) / np.sum(r_c * r_c, axis=-1)
    drho_in = drho + np.stack([-w * rho[..., 1], w * rho[..., 0], np.zeros_like(w)], axis=-1)
    r_d = r_c + np.einsum("...ji,...j->...i", C, rho)
    v_d = v_c + np.einsum("...ji,...j->...i", C, drho_in)
    return r_d, v_d


# ----------------------------------------------------------------------------------------
# perturbations and propagation
# ----------------------------------------------------------------------------------------
def accel_two_body_j2(
    r: ArrayLike, mu: float = MU_EARTH, j2: float = J2, r_e: float = R_EARTH
) -> FloatArray:
    """Point-mass plus J2 gravitational acceleration in ECI (vectorized over ``(..., 3)``).

    ``a = -mu r / |r|^3 - 3/2 J2 mu R_E^2 / |r|^5 [x (1 - 5 z^2/|r|^2),
    y (1 - 5 z^2/|r|^2), z (3 - 5 z^2/|r|^2)]`` (Vallado 2013, Eq. 8-30). Pass ``j2=0`` for
    two-body motion.
    """
    r = np.asarray(r, dtype=float)
    r2 = np.sum(r * r, axis=-1, keepdims=True)
    r_mag = np.sqrt(r2)
    acc = -mu * r / (r2 * r_mag)
    if j2 != 0.0:
        z2_r2 = r[..., 2:3] ** 2 / r2
        k = -1.5 * j2 * mu * r_e**2 / (r2 * r2 * r_mag)
        fac = np.concatenate([1.0 - 5.0 * z2_r2, 1.0 - 5.0 * z2_r2, 3.0 - 5.0 * z2_r2], axis=-1)
        acc = acc + k * r * fac
    return acc


def j2_secular_rates(
    oe: ArrayLike, mu: float = MU_EARTH, j2: float = J2, r_e: float = R_EARTH
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """First-order J2 secular rates of the mean elements (vectorized).

    With ``eta = sqrt(1 - e^2)`` and ``kappa = 3/4 J2 R_E^2 sqrt(mu) / (a^(7/2) eta^4)``
    (Koenig, Guffanti & D'Amico 2017, Eqs. 13-14; Vallado 2013, Eq. 9-41):

    * ``raan_dot = -2 kappa cos i``
    * ``argp_dot = kappa (5 cos^2 i - 1)``
    * ``M_dot = n + kappa eta (3 cos^2 i - 1)`` (total mean-anomaly rate, including ``n``)

    Returns
    -------
    raan_dot, argp_dot, M_dot
        Rates in rad/s with the batch shape of ``oe``.
    """
    oe = validate_oe(oe)
    return _secular_rates(oe[..., 0], oe[..., 1] ** 2, np.cos(oe[..., 2]), mu, j2, r_e)


def _secular_rates(
    a: FloatArray, e2: FloatArray, ci: FloatArray, mu: float, j2: float, r_e: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``(raan_dot, argp_dot, M_dot)`` of :func:`j2_secular_rates` from ``a``, ``e^2``, ``cos i``
    (no validation: the fast core of the mean propagators)."""
    eta = np.sqrt(1.0 - e2)
    kappa = 0.75 * j2 * r_e**2 * np.sqrt(mu) / (a**3.5 * eta**4)
    n = np.sqrt(mu / a**3)
    return -2.0 * kappa * ci, kappa * (5.0 * ci**2 - 1.0), n + kappa * eta * (3.0 * ci**2 - 1.0)


def propagate_mean_qns(
    qns: FloatArray, dt: ArrayLike, mu: float = MU_EARTH, j2: float = J2, r_e: float = R_EARTH
) -> FloatArray:
    """Propagate MEAN quasi-nonsingular elements ``(a, u, ex, ey, i, raan)`` with secular J2.

    The same model as :func:`propagate_mean_j2` in nonsingular form: ``a, i`` and ``e`` fixed,
    ``u += (argp_dot + M_dot) dt``, ``(ex, ey)`` rotated by ``argp_dot dt``,
    ``raan += raan_dot dt`` (angles not wrapped). Smooth in ``(ex, ey)`` through ``e = 0``,
    which is why the nonlinear ROE flow uses it. Not validated (fast core): pass elements of
    a bound orbit.
    """
    qns = np.asarray(qns, dtype=float)
    dt = np.asarray(dt, dtype=float)
    a, u, ex, ey, i, raan = np.moveaxis(qns, -1, 0)
    raan_dot, argp_dot, M_dot = _secular_rates(a, ex**2 + ey**2, np.cos(i), mu, j2, r_e)
    c, s = np.cos(argp_dot * dt), np.sin(argp_dot * dt)
    a, i = np.broadcast_to(a, c.shape), np.broadcast_to(i, c.shape)
    return np.stack(
        [a, u + (argp_dot + M_dot) * dt, c * ex - s * ey, s * ex + c * ey, i, raan + raan_dot * dt],
        axis=-1,
    )


def _broadcast_dt(oe: FloatArray, dt: ArrayLike) -> tuple[FloatArray, FloatArray]:
    dt = _as_float_array(dt, "dt")
    _check_finite(dt, "dt")
    shape = np.broadcast_shapes(oe.shape[:-1], dt.shape)
    return np.broadcast_to(oe, (*shape, 6)).copy(), np.broadcast_to(dt, shape)


def propagate_kepler(oe: ArrayLike, dt: ArrayLike, mu: float = MU_EARTH) -> FloatArray:
    """Keplerian propagation: advance the mean anomaly by ``n dt`` (other elements fixed).

    Parameters
    ----------
    oe
        Elements at the initial time, shape ``(..., 6)``.
    dt
        Time offsets [s]; broadcast against the batch shape of ``oe``
        (e.g. ``oe`` of shape ``(6,)`` and ``dt`` of shape ``(K,)`` give ``(K, 6)``).

    Returns
    -------
    numpy.ndarray
        Propagated elements with ``M`` wrapped to ``[0, 2 pi)``.
    """
    oe = validate_oe(oe)
    out, dt = _broadcast_dt(oe, dt)
    out[..., 5] = wrap_angle(out[..., 5] + np.sqrt(mu / out[..., 0] ** 3) * dt)
    return out


def propagate_mean_j2(
    oe: ArrayLike, dt: ArrayLike, mu: float = MU_EARTH, j2: float = J2, r_e: float = R_EARTH
) -> FloatArray:
    """Propagate MEAN elements with the first-order J2 secular rates (vectorized).

    ``a, e, i`` are constant; ``raan, argp, M`` drift linearly with
    :func:`j2_secular_rates`. This is the absolute model underlying the STM of Koenig et al.
    (2017); the chief elements at the nodes of a planning horizon are obtained with it.

    Parameters
    ----------
    oe
        Mean elements at the initial time, shape ``(..., 6)``.
    dt
        Time offsets [s], broadcast against the batch shape of ``oe``.
    """
    oe = validate_oe(oe)
    raan_dot, argp_dot, M_dot = j2_secular_rates(oe, mu, j2, r_e)
    out, dt = _broadcast_dt(oe, dt)
    raan_dot, argp_dot, M_dot = (np.broadcast_to(x, dt.shape) for x in (raan_dot, argp_dot, M_dot))
    out[..., 3] = wrap_angle(out[..., 3] + raan_dot * dt)
    out[..., 4] = wrap_angle(out[..., 4] + argp_dot * dt)
    out[..., 5] = wrap_angle(out[..., 5] + M_dot * dt)
    return out


# ----------------------------------------------------------------------------------------
# dataclass
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class OrbitalElements:
    """Validated classical orbital elements of one orbit (SI units, radians).

    Attributes
    ----------
    a : float
        Semi-major axis [m], ``>= R_EARTH``.
    e : float
        Eccentricity, ``0 <= e < 1``.
    i : float
        Inclination [rad], ``0 <= i <= pi``.
    raan, argp, M : float
        Right ascension of the ascending node, argument of periapsis and mean anomaly
        [rad] (any real value; not wrapped).
    """

    a: float
    e: float
    i: float
    raan: float
    argp: float
    M: float

    def __post_init__(self) -> None:
        for field in _FIELDS:
            value = getattr(self, field)
            try:
                value = float(value)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"{field}: expected a real number, got {shown(value)}") from exc
            object.__setattr__(self, field, value)
        validate_oe(np.array([getattr(self, f) for f in _FIELDS]), "OrbitalElements")

    @classmethod
    def from_degrees(
        cls, a: float, e: float, i_deg: float, raan_deg: float, argp_deg: float, M_deg: float
    ) -> OrbitalElements:
        """Build from ``a`` [m], ``e`` and angles in degrees."""
        return cls(
            a, e, np.deg2rad(i_deg), np.deg2rad(raan_deg), np.deg2rad(argp_deg), np.deg2rad(M_deg)
        )

    @classmethod
    def from_array(cls, oe: ArrayLike) -> OrbitalElements:
        """Build from an array ``(a, e, i, raan, argp, M)`` of shape ``(6,)``."""
        arr = _as_float_array(oe, "oe")
        if arr.shape != (6,):
            raise ValueError(f"oe: expected shape (6,), got {arr.shape}")
        return cls(*arr)

    def to_array(self) -> FloatArray:
        """Return ``(a, e, i, raan, argp, M)`` as a float array of shape ``(6,)``."""
        return np.array([self.a, self.e, self.i, self.raan, self.argp, self.M])

    def to_qns(self) -> FloatArray:
        """Quasi-nonsingular elements ``(a, u, ex, ey, i, raan)``, see :func:`oe_to_qns`."""
        return oe_to_qns(self.to_array())

    @property
    def mean_motion(self) -> float:
        """Keplerian mean motion [rad/s]."""
        return float(mean_motion(self.a))

    @property
    def period(self) -> float:
        """Keplerian orbital period [s]."""
        return 2.0 * np.pi / self.mean_motion

    def __array__(self, dtype=None, copy=None) -> FloatArray:
        arr = self.to_array()
        return arr if dtype is None else arr.astype(dtype)
