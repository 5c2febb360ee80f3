"""Quasi-nonsingular relative orbital elements (ROE): exact maps, linear maps, STMs, inputs.

Conventions (see also :mod:`scpformer.dynamics.orbits`)
------------------------------------------------------
* Chief (target) and deputy (servicer) classical elements ``oe = (a, e, i, raan, argp, M)``.
* Dimensionless quasi-nonsingular ROE of the deputy w.r.t. the chief (D'Amico 2010,
  Eq. 2.22; Koenig et al. 2017, Eq. 2)::

      delta_alpha = (da, dlambda, dex, dey, dix, diy)
      da      = (a_d - a_c) / a_c
      dlambda = (u_d - u_c) + (raan_d - raan_c) cos i_c        (u = argp + M, mean)
      dex     = e_d cos argp_d - e_c cos argp_c
      dey     = e_d sin argp_d - e_c sin argp_c
      dix     = i_d - i_c
      diy     = (raan_d - raan_c) sin i_c

  Angle differences are wrapped to ``[-pi, pi)``.
* Scaled ROE ``a_c * delta_alpha`` [m] (:func:`scale_roe`) are the solver state. The
  linear maps :func:`psi_matrix` and :func:`control_input_matrix` act on SCALED ROE; the
  STMs are the same for both because ``a_c`` is constant in the mean dynamics.
* RTN: relative position [m] and velocity [m/s] of the deputy in the chief's rotating
  RTN frame (osculating Keplerian frame rate), shape ``(..., 6)``.

The exact maps (:func:`oe_to_roe`, :func:`roe_to_oe`, :func:`roe_to_rtn_exact`,
:func:`rtn_to_roe_exact`) are nonlinear and use dimensionless ROE.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from scpformer.dynamics.orbits import (
    J2,
    MU_EARTH,
    R_EARTH,
    OrbitalElements,
    eci_to_oe,
    eci_to_rtn,
    mean_to_true,
    oe_to_eci,
    oe_to_qns,
    propagate_mean_qns,
    rtn_to_eci,
    validate_oe,
    wrap_angle,
    wrap_to_pi,
)

__all__ = [
    "control_input_matrix",
    "oe_to_roe",
    "propagate_roe_mean",
    "psi_matrix",
    "roe_flow_jacobian",
    "roe_to_oe",
    "roe_to_rtn_exact",
    "rtn_dv_to_roe",
    "rtn_to_roe_exact",
    "scale_roe",
    "stm_j2",
    "stm_kepler",
    "unscale_roe",
]

FloatArray = NDArray[np.float64]
Model = Literal["eccentric", "near_circular"]
_SIN_I_MIN = 1e-10


def _as_vec(x: ArrayLike, size: int, name: str) -> FloatArray:
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float array ({exc})") from exc
    if arr.ndim == 0 or arr.shape[-1] != size:
        raise ValueError(f"{name}: expected shape (..., {size}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def _chief(oe_chief: ArrayLike | OrbitalElements) -> FloatArray:
    return validate_oe(oe_chief, "oe_chief")


def _check_model(model: str) -> None:
    if model not in ("eccentric", "near_circular"):
        raise ValueError(f"model: expected 'eccentric' or 'near_circular', got {model!r}")


def _cot_i(oe: FloatArray, need: FloatArray | bool = True) -> FloatArray:
    """cot(i) of the chief; raises where it is needed and the orbit is equatorial."""
    si = np.sin(oe[..., 2])
    bad = (np.abs(si) < _SIN_I_MIN) & np.asarray(need)
    if np.any(bad):
        raise ValueError(
            "oe_chief.i: quasi-nonsingular ROE are singular for an equatorial chief orbit "
            "(sin i = 0)"
        )
    return np.cos(oe[..., 2]) / np.where(np.abs(si) < _SIN_I_MIN, 1.0, si)


# ----------------------------------------------------------------------------------------
# exact nonlinear maps
# ----------------------------------------------------------------------------------------
def oe_to_roe(
    oe_chief: ArrayLike | OrbitalElements, oe_deputy: ArrayLike | OrbitalElements
) -> FloatArray:
    """Exact quasi-nonsingular ROE of the deputy w.r.t. the chief (D'Amico 2010, Eq. 2.22).

    Parameters
    ----------
    oe_chief, oe_deputy
        Classical elements ``(a, e, i, raan, argp, M)``, shapes broadcastable
        ``(..., 6)``.

    Returns
    -------
    numpy.ndarray
        Dimensionless ROE ``(da, dlambda, dex, dey, dix, diy)``, shape ``(..., 6)``.
    """
    c = _chief(oe_chief)
    d = validate_oe(oe_deputy, "oe_deputy")
    a_c, e_c, i_c, O_c, w_c, M_c = np.moveaxis(c, -1, 0)
    a_d, e_d, i_d, O_d, w_d, M_d = np.moveaxis(d, -1, 0)
    dO = wrap_to_pi(O_d - O_c)
    du = wrap_to_pi((w_d + M_d) - (w_c + M_c))
    return np.stack(
        [
            (a_d - a_c) / a_c,
            wrap_to_pi(du + dO * np.cos(i_c)),
            e_d * np.cos(w_d) - e_c * np.cos(w_c),
            e_d * np.sin(w_d) - e_c * np.sin(w_c),
            i_d - i_c,
            dO * np.sin(i_c),
        ],
        axis=-1,
    )


def roe_to_oe(oe_chief: ArrayLike | OrbitalElements, roe: ArrayLike) -> FloatArray:
    """Deputy classical elements from chief elements and dimensionless ROE (exact inverse).

    Inverts D'Amico (2010) Eq. 2.22: ``a_d = a_c (1 + da)``,
    ``raan_d = raan_c + diy / sin i_c``, ``u_d = u_c + dlambda - (raan_d - raan_c) cos i_c``,
    ``e_d (cos, sin) argp_d = e_c (cos, sin) argp_c + (dex, dey)``, ``i_d = i_c + dix``.
    Angles are returned in ``[0, 2 pi)``; ``argp_d = 0`` if ``e_d == 0``.

    Raises
    ------
    ValueError
        On bad shapes/values, an equatorial chief (``diy`` undefined), or a resulting
        deputy orbit that is not physical (``a < R_E``, ``e >= 1``, ``i`` outside [0, pi]).
    """
    c = _chief(oe_chief)
    roe = _as_vec(roe, 6, "roe")
    c, roe = np.broadcast_arrays(c, roe)
    a_c, e_c, i_c, O_c, w_c, M_c = np.moveaxis(c, -1, 0)
    da, dl, dex, dey, dix, diy = np.moveaxis(roe, -1, 0)
    si = np.sin(i_c)
    if np.any((np.abs(si) < _SIN_I_MIN) & (diy != 0.0)):
        raise ValueError(
            "oe_chief.i: diy cannot be inverted for an equatorial chief orbit (sin i = 0)"
        )
    dO = np.where(np.abs(si) < _SIN_I_MIN, 0.0, diy / np.where(si == 0.0, 1.0, si))
    u_d = (w_c + M_c) + dl - dO * np.cos(i_c)
    ex_d = e_c * np.cos(w_c) + dex
    ey_d = e_c * np.sin(w_c) + dey
    e_d = np.hypot(ex_d, ey_d)
    w_d = np.where(e_d > 0.0, np.arctan2(ey_d, ex_d), 0.0)
    oe_d = np.stack(
        [
            a_c * (1.0 + da),
            e_d,
            i_c + dix,
            wrap_angle(O_c + dO),
            wrap_angle(w_d),
            wrap_angle(u_d - w_d),
        ],
        axis=-1,
    )
    return validate_oe(oe_d, "deputy (from roe)")


def scale_roe(oe_chief: ArrayLike | OrbitalElements, roe: ArrayLike) -> FloatArray:
    """Scaled ROE ``a_c * delta_alpha`` [m] from dimensionless ROE."""
    c = _chief(oe_chief)
    return c[..., 0:1] * _as_vec(roe, 6, "roe")


def unscale_roe(oe_chief: ArrayLike | OrbitalElements, roe_m: ArrayLike) -> FloatArray:
    """Dimensionless ROE from scaled ROE ``a_c * delta_alpha`` [m]."""
    c = _chief(oe_chief)
    return _as_vec(roe_m, 6, "roe_m") / c[..., 0:1]


def roe_to_rtn_exact(oe_chief: ArrayLike | OrbitalElements, roe: ArrayLike) -> FloatArray:
    """Exact relative RTN state from dimensionless ROE, through both inertial states.

    deputy elements (:func:`roe_to_oe`) -> both ECI states (two-body
    :func:`~scpformer.dynamics.orbits.oe_to_eci`) -> chief RTN frame
    (:func:`~scpformer.dynamics.orbits.eci_to_rtn`).

    Returns
    -------
    numpy.ndarray
        ``(dr_R, dr_T, dr_N, dv_R, dv_T, dv_N)`` [m, m/s], shape ``(..., 6)``.
    """
    c = _chief(oe_chief)
    d = roe_to_oe(c, roe)
    r_c, v_c = oe_to_eci(c)
    r_d, v_d = oe_to_eci(d)
    return eci_to_rtn(r_c, v_c, r_d, v_d)


def rtn_to_roe_exact(oe_chief: ArrayLike | OrbitalElements, rtn: ArrayLike) -> FloatArray:
    """Exact dimensionless ROE from a relative RTN state (inverse of :func:`roe_to_rtn_exact`).

    Raises
    ------
    ValueError
        On bad shapes/values or if the deputy state is not a bound orbit above R_E.
    """
    c = _chief(oe_chief)
    rtn = _as_vec(rtn, 6, "rtn")
    r_c, v_c = oe_to_eci(c)
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn)
    return oe_to_roe(c, eci_to_oe(r_d, v_d))


# ----------------------------------------------------------------------------------------
# first-order map Psi: scaled ROE -> RTN
# ----------------------------------------------------------------------------------------
def _chief_geometry(c: FloatArray) -> dict[str, FloatArray]:
    a, e, i, _, w, M = np.moveaxis(c, -1, 0)
    n = np.sqrt(MU_EARTH / a**3)
    eta = np.sqrt(1.0 - e**2)
    f = mean_to_true(M, e)
    theta = w + f  # true argument of latitude
    ex, ey = e * np.cos(w), e * np.sin(w)
    ec = ex * np.cos(theta) + ey * np.sin(theta)  # e cos f
    es = ex * np.sin(theta) - ey * np.cos(theta)  # e sin f
    k = 1.0 + ec
    return dict(a=a, e=e, i=i, n=n, eta=eta, theta=theta, ex=ex, ey=ey, ec=ec, es=es, k=k, u=w + M)


def _map_geometry(
    oe_chief: ArrayLike | OrbitalElements, model: Model
) -> tuple[FloatArray, dict[str, FloatArray]]:
    """The chief elements and their geometry for the first-order maps (``Psi``, ``B``) of
    ``model`` (checked): :func:`_chief_geometry` with the cosine and sine of the mean argument
    of latitude ``u`` (``cu``, ``su``: the near-circular maps) and of the true one ``theta``
    (``ct``, ``st``: the eccentric maps)."""
    _check_model(model)
    c = _chief(oe_chief)
    g = _chief_geometry(c)
    g.update(cu=np.cos(g["u"]), su=np.sin(g["u"]), ct=np.cos(g["theta"]), st=np.sin(g["theta"]))
    return c, g


def psi_matrix(oe_chief: ArrayLike | OrbitalElements, model: Model = "eccentric") -> FloatArray:
    """First-order map ``Psi`` from scaled ROE ``a_c * delta_alpha`` [m] to RTN [m, m/s].

    ``rtn ~= Psi(t) @ (a_c * delta_alpha(t))`` (ART paper Eq. 9).

    ``model="eccentric"`` (default) is the exact Jacobian of the Keplerian map at zero
    separation, valid for any ``0 <= e < 1`` (equivalent to the eccentric maps of Sullivan
    & D'Amico 2017 and Guffanti & D'Amico 2023). It is derived from
    ``dr_R = dr``, ``dr_T = r (dtheta + cos i draan)``, ``dr_N = r (sin theta di - cos theta
    sin i draan)`` with ``theta`` the chief true argument of latitude, ``r = a eta^2 / k``,
    ``k = 1 + e cos f``, written free of ``1/e`` singularities. Velocity rows are the time
    derivatives of the position rows along the chief orbit plus the Keplerian drift
    ``dlambda_dot = -3/2 n da``. For ``e = 0`` it reduces exactly to the near-circular map.

    ``model="near_circular"`` is D'Amico (2010) Eq. 2.24 evaluated at the chief mean
    argument of latitude ``u``::

        [[1,      0, -cos u,    -sin u,      0,       0      ],
         [0,      1,  2 sin u,  -2 cos u,    0,       0      ],
         [0,      0,  0,         0,          sin u,  -cos u  ],
         [0,      0,  n sin u,  -n cos u,    0,       0      ],
         [-3n/2,  0,  2n cos u,  2n sin u,   0,       0      ],
         [0,      0,  0,         0,          n cos u, n sin u]]

    Parameters
    ----------
    oe_chief
        Chief (osculating) classical elements at the evaluation time, ``(6,)`` or
        ``(K, 6)``.
    model
        ``"eccentric"`` or ``"near_circular"``.

    Returns
    -------
    numpy.ndarray
        ``Psi`` of shape ``(..., 6, 6)``.
    """
    c, g = _map_geometry(oe_chief, model)
    n = g["n"]
    P = np.zeros((*n.shape, 6, 6))
    if model == "near_circular":
        cu, su = g["cu"], g["su"]
        P[..., 0, 0] = 1.0
        P[..., 0, 2] = -cu
        P[..., 0, 3] = -su
        P[..., 1, 1] = 1.0
        P[..., 1, 2] = 2.0 * su
        P[..., 1, 3] = -2.0 * cu
        P[..., 2, 4] = su
        P[..., 2, 5] = -cu
        P[..., 3, 2] = n * su
        P[..., 3, 3] = -n * cu
        P[..., 4, 0] = -1.5 * n
        P[..., 4, 2] = 2.0 * n * cu
        P[..., 4, 3] = 2.0 * n * su
        P[..., 5, 4] = n * cu
        P[..., 5, 5] = n * su
        return P

    eta, k, ec, es = g["eta"], g["k"], g["ec"], g["es"]
    ex, ey, ct, st = g["ex"], g["ey"], g["ct"], g["st"]
    cot_i = _cot_i(c, need=g["e"] > 0.0)
    thd = n * k**2 / eta**3  # true-argument-of-latitude rate / (1)
    b = 1.0 / (eta * (1.0 + eta))
    rho = eta**2 / k  # r / a

    # --- position, radial: dr_R / a = rho da + (es/eta)(dl - cot i diy)
    #     + (-cos th + b es ey) dex + (-sin th - b es ex) dey
    P[..., 0, 0] = rho
    P[..., 0, 1] = es / eta
    P[..., 0, 2] = -ct + b * es * ey
    P[..., 0, 3] = -st - b * es * ex
    P[..., 0, 5] = -(es / eta) * cot_i
    # --- position, along-track: dr_T / a = (k/eta) dl + Q1/Q2 terms - (k/eta - rho) cot i diy
    q1 = 2.0 + ec * k * b
    q2 = es * (eta / k + k / (1.0 + eta)) / eta
    P[..., 1, 1] = k / eta
    P[..., 1, 2] = q1 * st - q2 * ct
    P[..., 1, 3] = -q1 * ct - q2 * st
    P[..., 1, 5] = -(k / eta - rho) * cot_i
    # --- position, normal: dr_N / a = rho (sin th dix - cos th diy)
    P[..., 2, 4] = rho * st
    P[..., 2, 5] = -rho * ct

    # --- velocity rows: d/dt of position rows (chief motion) + column da gets -3/2 n * col dl
    rho_dot = n * es / eta
    # radial
    P[..., 3, 0] = rho_dot - 1.5 * n * P[..., 0, 1]
    P[..., 3, 1] = ec * thd / eta
    P[..., 3, 2] = thd * (st + b * ec * ey)
    P[..., 3, 3] = thd * (-ct - b * ec * ex)
    P[..., 3, 5] = -(ec * thd / eta) * cot_i
    # along-track
    q1_dot = -es * thd * (k + ec) * b
    q2_dot = thd * (eta * (ec + g["e"] ** 2) / k**2 + (ec * k - es**2) / (1.0 + eta)) / eta
    P[..., 4, 0] = -1.5 * n * P[..., 1, 1]
    P[..., 4, 1] = -es * thd / eta
    P[..., 4, 2] = q1_dot * st + q1 * ct * thd - q2_dot * ct + q2 * st * thd
    P[..., 4, 3] = -q1_dot * ct + q1 * st * thd - q2_dot * st - q2 * ct * thd
    P[..., 4, 5] = cot_i * es * (thd + n) / eta
    # normal
    P[..., 5, 4] = rho_dot * st + n * k * ct / eta
    P[..., 5, 5] = -rho_dot * ct + n * k * st / eta
    return P


# ----------------------------------------------------------------------------------------
# state transition matrices
# ----------------------------------------------------------------------------------------
def _stm_prep(
    oe_chief: ArrayLike | OrbitalElements, dt: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    c = _chief(oe_chief)
    try:
        dt = np.asarray(dt, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"dt: cannot be converted to a float array ({exc})") from exc
    if not np.all(np.isfinite(dt)):
        raise ValueError("dt: contains NaN or inf")
    shape = np.broadcast_shapes(c.shape[:-1], dt.shape)
    return np.broadcast_to(c, (*shape, 6)), np.broadcast_to(dt, shape)


def stm_kepler(oe_chief: ArrayLike | OrbitalElements, dt: ArrayLike) -> FloatArray:
    """Keplerian ROE state transition matrix (D'Amico 2010, Eq. 2.30; Koenig et al. 2017).

    Identity except ``Phi[1, 0] = -3/2 n dt`` (relative mean longitude drift). Applies to
    dimensionless and scaled ROE alike.

    Parameters
    ----------
    oe_chief
        Chief elements at the initial time, ``(..., 6)``.
    dt
        Propagation time(s) [s], broadcast against the batch shape of ``oe_chief``
        (e.g. ``(6,)`` with ``(K,)`` gives ``(K, 6, 6)``).

    Returns
    -------
    numpy.ndarray
        ``Phi`` of shape ``(..., 6, 6)``.
    """
    c, dt = _stm_prep(oe_chief, dt)
    n = np.sqrt(MU_EARTH / c[..., 0] ** 3)
    Phi = np.broadcast_to(np.eye(6), (*dt.shape, 6, 6)).copy()
    Phi[..., 1, 0] = -1.5 * n * dt
    return Phi


def stm_j2(
    oe_chief: ArrayLike | OrbitalElements,
    dt: ArrayLike,
    *,
    j2: float = J2,
    r_e: float = R_EARTH,
    mu: float = MU_EARTH,
) -> FloatArray:
    """J2-perturbed STM of MEAN quasi-nonsingular ROE (Koenig, Guffanti & D'Amico 2017).

    Closed form of Koenig et al. (2017), Appendix (quasi-nonsingular J2 STM), i.e. the
    Jacobian at zero separation of the first-order J2 secular drift of both spacecraft
    (exact for any chief eccentricity). With ``tau = dt``, ``eta = sqrt(1 - e^2)``,
    ``kappa = 3/4 J2 R_E^2 sqrt(mu) / (a^(7/2) eta^4)``, ``E = 1 + eta``, ``F = 4 + 3 eta``,
    ``G = 1/eta^2``, ``P = 3 cos^2 i - 1``, ``Q = 5 cos^2 i - 1``, ``S = sin 2i``,
    ``T = sin^2 i``, ``argp_dot = kappa Q``, chief ``(ex_i, ey_i)`` at the initial time and
    ``(ex_f, ey_f)`` rotated by ``argp_dot tau``::

        Phi = [[1, 0, 0, 0, 0, 0],
               [-(7/2 kappa E P + 3/2 n) tau, 1, kappa ex_i F G P tau,
                kappa ey_i F G P tau, -kappa F S tau, 0],
               [7/2 kappa ey_f Q tau, 0, cos(w' tau) - 4 kappa ex_i ey_f G Q tau,
                -sin(w' tau) - 4 kappa ey_i ey_f G Q tau, 5 kappa ey_f S tau, 0],
               [-7/2 kappa ex_f Q tau, 0, sin(w' tau) + 4 kappa ex_i ex_f G Q tau,
                cos(w' tau) + 4 kappa ey_i ex_f G Q tau, -5 kappa ex_f S tau, 0],
               [0, 0, 0, 0, 1, 0],
               [7/2 kappa S tau, 0, -4 kappa ex_i G S tau, -4 kappa ey_i G S tau,
                2 kappa T tau, 1]]

    The STM propagates MEAN ROE with MEAN chief elements; it is the same for dimensionless
    and scaled ROE. With ``j2=0`` it equals :func:`stm_kepler`.

    Parameters
    ----------
    oe_chief
        Chief MEAN elements at the initial time, ``(..., 6)``.
    dt
        Propagation time(s) [s], broadcast against the batch shape of ``oe_chief``.
    j2, r_e, mu
        Gravity-field constants (defaults: module constants).

    Returns
    -------
    numpy.ndarray
        ``Phi`` of shape ``(..., 6, 6)``.
    """
    c, tau = _stm_prep(oe_chief, dt)
    a, e, i, w = c[..., 0], c[..., 1], c[..., 2], c[..., 4]
    n = np.sqrt(mu / a**3)
    eta = np.sqrt(1.0 - e**2)
    kappa = 0.75 * j2 * r_e**2 * np.sqrt(mu) / (a**3.5 * eta**4)
    E = 1.0 + eta
    F = 4.0 + 3.0 * eta
    G = 1.0 / eta**2
    ci, si = np.cos(i), np.sin(i)
    P = 3.0 * ci**2 - 1.0
    Q = 5.0 * ci**2 - 1.0
    S = 2.0 * si * ci
    T = si**2
    w_dot = kappa * Q
    exi, eyi = e * np.cos(w), e * np.sin(w)
    wf = w + w_dot * tau
    exf, eyf = e * np.cos(wf), e * np.sin(wf)
    cw, sw = np.cos(w_dot * tau), np.sin(w_dot * tau)
    kt = kappa * tau

    Phi = np.broadcast_to(np.eye(6), (*tau.shape, 6, 6)).copy()
    Phi[..., 1, 0] = -(3.5 * kappa * E * P + 1.5 * n) * tau
    Phi[..., 1, 2] = kt * exi * F * G * P
    Phi[..., 1, 3] = kt * eyi * F * G * P
    Phi[..., 1, 4] = -kt * F * S
    Phi[..., 2, 0] = 3.5 * kt * eyf * Q
    Phi[..., 2, 2] = cw - 4.0 * kt * exi * eyf * G * Q
    Phi[..., 2, 3] = -sw - 4.0 * kt * eyi * eyf * G * Q
    Phi[..., 2, 4] = 5.0 * kt * eyf * S
    Phi[..., 3, 0] = -3.5 * kt * exf * Q
    Phi[..., 3, 2] = sw + 4.0 * kt * exi * exf * G * Q
    Phi[..., 3, 3] = cw + 4.0 * kt * eyi * exf * G * Q
    Phi[..., 3, 4] = -5.0 * kt * exf * S
    Phi[..., 5, 0] = 3.5 * kt * S
    Phi[..., 5, 2] = -4.0 * kt * exi * G * S
    Phi[..., 5, 3] = -4.0 * kt * eyi * G * S
    Phi[..., 5, 4] = 2.0 * kt * T
    return Phi


# ----------------------------------------------------------------------------------------
# nonlinear mean-ROE flow (secular J2) and its Jacobian
# ----------------------------------------------------------------------------------------
def propagate_roe_mean(
    oe_chief: ArrayLike | OrbitalElements,
    roe: ArrayLike,
    dt: ArrayLike,
    *,
    j2: float = J2,
    r_e: float = R_EARTH,
    mu: float = MU_EARTH,
    chief_is_qns: bool = False,
) -> FloatArray:
    """Nonlinear flow of MEAN dimensionless ROE under first-order secular J2 (any separation).

    Deputy mean quasi-nonsingular elements from the chief's and the ROE (the inverse of
    D'Amico 2010, Eq. 2.22, as in :func:`roe_to_oe`), both spacecraft propagated with their
    own secular J2 rates (:func:`~scpformer.dynamics.orbits.propagate_mean_qns`), ROE formed
    again. Exact in mean elements for the first-order secular J2 model; its Jacobian at zero
    separation is the STM of Koenig et al. (2017) (:func:`stm_j2`), whose neglected
    second-order terms (e.g. ``15/8 n a da^2 dt`` along-track) reach tens of metres per orbit
    at kilometres of ``a da``. ``j2=0`` gives the Keplerian flow.

    Parameters
    ----------
    oe_chief
        Chief MEAN elements at the initial time, ``(..., 6)``.
    roe
        Dimensionless ROE at the initial time, ``(..., 6)`` (broadcast with ``oe_chief``).
    dt
        Propagation time(s) [s], broadcast against the batch shape.
    chief_is_qns
        ``oe_chief`` holds the chief's quasi-nonsingular elements, used as given (no
        validation: the fast path of the solvers' inner loops).

    Returns
    -------
    numpy.ndarray
        Dimensionless ROE after ``dt``, shape ``(..., 6)``.
    """
    qc = np.asarray(oe_chief, dtype=float) if chief_is_qns else oe_to_qns(_chief(oe_chief))
    return _roe_flow(qc, _as_vec(roe, 6, "roe"), dt, mu, j2, r_e)


def roe_to_qns_offset(qc: FloatArray, roe: FloatArray) -> FloatArray:
    """Deputy minus chief quasi-nonsingular elements ``(a, u, ex, ey, i, raan)`` from
    dimensionless ROE (inverse of D'Amico 2010, Eq. 2.22; broadcasting, not validated)."""
    sin_i = np.sin(qc[..., 4])
    if np.any(np.abs(sin_i) < _SIN_I_MIN):
        raise ValueError("oe_chief.i: the ROE are singular for an equatorial chief orbit")
    d_raan = roe[..., 5] / sin_i
    parts = (qc[..., 0] * roe[..., 0], roe[..., 1] - d_raan * np.cos(qc[..., 4]), roe[..., 2],
             roe[..., 3], roe[..., 4], d_raan)  # fmt: skip
    return np.stack(np.broadcast_arrays(*parts), axis=-1)


def qns_offset_to_roe(qc: FloatArray, diff: FloatArray) -> FloatArray:
    """Dimensionless ROE from deputy minus chief quasi-nonsingular elements (D'Amico 2010,
    Eq. 2.22; angle differences wrapped to ``[-pi, pi)``)."""
    d_raan = wrap_to_pi(diff[..., 5])
    parts = (diff[..., 0] / qc[..., 0], wrap_to_pi(diff[..., 1] + d_raan * np.cos(qc[..., 4])),
             diff[..., 2], diff[..., 3], diff[..., 4], d_raan * np.sin(qc[..., 4]))  # fmt: skip
    return np.stack(np.broadcast_arrays(*parts), axis=-1)


def _roe_flow(
    qc: FloatArray, roe: FloatArray, dt: ArrayLike, mu: float, j2: float, r_e: float
) -> FloatArray:
    """:func:`propagate_roe_mean` from the chief's quasi-nonsingular elements (broadcasting)."""
    qc_t = propagate_mean_qns(qc, dt, mu, j2, r_e)  # the chief once, not per deputy
    diff = propagate_mean_qns(qc + roe_to_qns_offset(qc, roe), dt, mu, j2, r_e) - qc_t
    return qns_offset_to_roe(qc_t, diff)


def roe_flow_jacobian(
    oe_chief: ArrayLike | OrbitalElements,
    roe: ArrayLike,
    dt: ArrayLike,
    *,
    j2: float = J2,
    step: float = 1e-7,
    chief_is_qns: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """:func:`propagate_roe_mean` and its Jacobian w.r.t. the initial ROE, batched.

    Central differences with ``step`` (dimensionless, 0.7 m at LEO): the flow is smooth (a few
    trigonometric functions of linear drifts), so the truncation error is ``O(step^2)`` and the
    Jacobian agrees with :func:`stm_j2` to ~1e-8 at zero separation (tested). The Jacobian is
    the same for scaled ROE. ``chief_is_qns`` as in :func:`propagate_roe_mean`.

    Returns
    -------
    flow, jacobian
        ROE after ``dt`` ``(..., 6)`` and ``d flow / d roe`` ``(..., 6, 6)``.
    """
    qc = np.asarray(oe_chief, dtype=float) if chief_is_qns else oe_to_qns(_chief(oe_chief))
    qc = qc[..., None, :]  # probes broadcast on a new axis
    roe = _as_vec(roe, 6, "roe")[..., None, :]
    dt = np.asarray(dt, dtype=float)[..., None]
    probes = np.concatenate([np.zeros((1, 6)), step * np.eye(6), -step * np.eye(6)])  # (13, 6)
    out = _roe_flow(qc, roe + probes, dt, MU_EARTH, j2, R_EARTH)
    jac = (out[..., 1:7, :] - out[..., 7:13, :]) / (2.0 * step)  # (..., column j, row)
    return out[..., 0, :], np.swapaxes(jac, -1, -2)


# ----------------------------------------------------------------------------------------
# impulsive control input
# ----------------------------------------------------------------------------------------
def control_input_matrix(
    oe_chief: ArrayLike | OrbitalElements, model: Model = "eccentric"
) -> FloatArray:
    """Impulsive input matrix ``B``: RTN delta-v [m/s] -> change of scaled ROE [m].

    ``Delta(a_c delta_alpha) = B @ dv_rtn`` (ART paper Eq. 10), from the Gauss variational
    equations evaluated on the chief orbit (first order in the separation).

    ``model="eccentric"`` (Chernick & D'Amico 2018, Eq. 7; Vallado 2013, Eq. 9-24) with
    ``eta = sqrt(1-e^2)``, true argument of latitude ``theta``, ``k = 1 + e cos f``::

        B = [[ 2/(n eta) e sin f,                      2 k/(n eta),                     0],
             [-eta/n (2 eta/k + e cos f/(1+eta)),     eta/n e sin f (1+1/k)/(1+eta),   0],
             [ eta/n sin theta,   eta/n ((1+1/k) cos theta + ex/k),  eta/n ey sin theta cot i/k],
             [-eta/n cos theta,   eta/n ((1+1/k) sin theta + ey/k), -eta/n ex sin theta cot i/k],
             [0, 0, eta/n cos theta / k],
             [0, 0, eta/n sin theta / k]]

    ``model="near_circular"`` (D'Amico 2010, Eq. 2.38; Gaias & D'Amico 2015) with the mean
    argument of latitude ``u``::

        B = 1/n [[0, 2, 0], [-2, 0, 0], [sin u, 2 cos u, 0], [-cos u, 2 sin u, 0],
                 [0, 0, cos u], [0, 0, sin u]]

    Parameters
    ----------
    oe_chief
        Chief (osculating) elements at the impulse time, ``(..., 6)``.
    model
        ``"eccentric"`` or ``"near_circular"``.

    Returns
    -------
    numpy.ndarray
        ``B`` of shape ``(..., 6, 3)`` [s].
    """
    c, g = _map_geometry(oe_chief, model)
    n = g["n"]
    B = np.zeros((*n.shape, 6, 3))
    if model == "near_circular":
        cu, su = g["cu"], g["su"]
        B[..., 0, 1] = 2.0 / n
        B[..., 1, 0] = -2.0 / n
        B[..., 2, 0] = su / n
        B[..., 2, 1] = 2.0 * cu / n
        B[..., 3, 0] = -cu / n
        B[..., 3, 1] = 2.0 * su / n
        B[..., 4, 2] = cu / n
        B[..., 5, 2] = su / n
        return B

    eta, k, ec, es = g["eta"], g["k"], g["ec"], g["es"]
    ex, ey, ct, st = g["ex"], g["ey"], g["ct"], g["st"]
    cot_i = _cot_i(c, need=g["e"] > 0.0)
    s = eta / n
    B[..., 0, 0] = 2.0 * es / (n * eta)
    B[..., 0, 1] = 2.0 * k / (n * eta)
    B[..., 1, 0] = -s * (2.0 * eta / k + ec / (1.0 + eta))
    B[..., 1, 1] = s * es * (1.0 + 1.0 / k) / (1.0 + eta)
    B[..., 2, 0] = s * st
    B[..., 2, 1] = s * ((1.0 + 1.0 / k) * ct + ex / k)
    B[..., 2, 2] = s * ey * st * cot_i / k
    B[..., 3, 0] = -s * ct
    B[..., 3, 1] = s * ((1.0 + 1.0 / k) * st + ey / k)
    B[..., 3, 2] = -s * ex * st * cot_i / k
    B[..., 4, 2] = s * ct / k
    B[..., 5, 2] = s * st / k
    return B


def rtn_dv_to_roe(
    oe_chief: ArrayLike | OrbitalElements, dv_rtn: ArrayLike, model: Model = "eccentric"
) -> FloatArray:
    """Change of scaled ROE [m] produced by impulsive RTN delta-v(s) [m/s]: ``B @ dv``.

    Parameters
    ----------
    oe_chief
        Chief elements at the impulse time(s), ``(..., 6)``.
    dv_rtn
        Delta-v in RTN [m/s], ``(..., 3)`` broadcast against ``oe_chief``.
    model
        See :func:`control_input_matrix`.

    Returns
    -------
    numpy.ndarray
        ``Delta(a_c delta_alpha)`` [m], shape ``(..., 6)``.
    """
    dv = _as_vec(dv_rtn, 3, "dv_rtn")
    B = control_input_matrix(oe_chief, model)
    return np.einsum("...ij,...j->...i", B, dv)
