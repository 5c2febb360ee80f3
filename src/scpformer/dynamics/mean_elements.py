"""Mean and osculating elements under J2 by numerical averaging; impulses on mean elements.

Notation (see :mod:`scpformer.dynamics.orbits`)
-----------------------------------------------
* ``o``: OSCULATING quasi-nonsingular elements ``(a, u, ex, ey, i, raan)`` of an ECI state.
* ``m = mean(o)``: MEAN elements, the one-orbit average of the osculating elements along the
  two-body + J2 motion started from ``o`` (over the spacecraft's own draconitic period), with
  the first-order secular drift of ``u`` and ``raan`` removed (:func:`average_qns`). This is
  the numerical counterpart of the first-order (Brouwer/Kozai) mean elements the ROE models
  of Koenig et al. (2017) are written in.

An impulse changes the osculating state exactly (two-body, instantaneous) but the mean
elements by ``Delta m = dm/do Delta o``: near a reference orbit ``o_c`` the map
``m(o) ~= m(o_c) + J (o - o_c)`` with ``J = dm/do`` (a 6x6 Jacobian, identity plus J2-order
terms) is what :func:`impulse_mean_qns` uses. The J2-order terms matter: the short-period
amplitudes scale with ``a^(-7/2)``, so a burn that raises ``a`` by kilometres moves the mean
eccentricity vector by metres more than the osculating one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from scpformer.dynamics.orbits import (
    J2,
    accel_two_body_j2,
    eci_to_oe,
    j2_secular_rates,
    oe_to_eci,
    oe_to_qns,
    qns_to_oe,
    rtn_dcm,
    rtn_to_eci,
    wrap_to_pi,
)
from scpformer.dynamics.roe import qns_offset_to_roe, roe_to_qns_offset

__all__ = [
    "MeanOscMap",
    "average_qns",
    "impulse_mean_qns",
    "impulse_roe",
    "impulse_roe_jacobian",
    "mean_osc_map",
    "osculating_to_mean_qns",
    "propagate_rk4",
    "qns_difference",
    "rtn_to_mean_roe",
]

FloatArray = NDArray[np.float64]
_ANGLES = [1, 5]  # u and raan in (a, u, ex, ey, i, raan)
# finite-difference steps of the Jacobian dm/do, per element [m, rad, -, -, rad, rad]
_STEPS = np.array([10.0, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6])


def qns_difference(q1: FloatArray, q0: FloatArray) -> FloatArray:
    """``q1 - q0`` with the ``u`` and ``raan`` differences wrapped to ``[-pi, pi)``."""
    d = np.asarray(q1, dtype=float) - np.asarray(q0, dtype=float)
    d[..., _ANGLES] = wrap_to_pi(d[..., _ANGLES])
    return d


def propagate_rk4(x0: FloatArray, t: FloatArray, substeps: int, j2: float = J2) -> FloatArray:
    """ECI states ``(..., T, 6)`` at the evenly spaced times ``t`` ``(..., T)`` (``t[..., 0] =
    0``, one grid per batch entry or one for all) from ``x0`` ``(..., 6)``: fixed-step RK4 of
    two-body + J2 (:func:`accel_two_body_j2`), ``substeps`` steps per output interval,
    vectorized over the batch."""
    x = np.array(x0, dtype=float)
    n_out = t.shape[-1]
    h = (t[..., 1:2] - t[..., 0:1]) / substeps if n_out > 1 else 0.0
    out = np.empty((*x.shape[:-1], n_out, 6))
    out[..., 0, :] = x

    def f(s: FloatArray) -> FloatArray:
        return np.concatenate([s[..., 3:], accel_two_body_j2(s[..., :3], j2=j2)], axis=-1)

    for k in range(1, n_out):
        for _ in range(substeps):
            k1 = f(x)
            k2 = f(x + 0.5 * h * k1)
            k3 = f(x + 0.5 * h * k2)
            k4 = f(x + h * k3)
            x = x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out[..., k, :] = x
    return out


def average_qns(q: FloatArray, t: FloatArray) -> FloatArray:
    """Mean elements ``(..., 6)`` from osculating samples ``q`` ``(..., S, 6)`` at ``t`` ``(.., S)``
    spanning one period: the sample mean, with ``u`` and ``raan`` unwrapped and their
    first-order secular J2 drift removed at the rates of the averaged ``(a, e, i)``
    themselves (so that an error in the mean ``a`` does not bias the mean ``u``)."""
    mean = q.mean(axis=-2)
    raan_dot, argp_dot, M_dot = j2_secular_rates(qns_to_oe(mean))
    u = np.unwrap(q[..., 1], axis=-1) - (argp_dot + M_dot)[..., None] * t
    raan = np.unwrap(q[..., 5], axis=-1) - raan_dot[..., None] * t  # (..., S)
    mean[..., 1], mean[..., 5] = u.mean(axis=-1), raan.mean(axis=-1)
    return mean


def osculating_to_mean_qns(
    x: FloatArray, period: FloatArray | float, samples: int = 48, substeps: int = 12
) -> FloatArray:
    """Mean quasi-nonsingular elements ``(..., 6)`` of ECI states ``x`` ``(..., 6)``: RK4
    propagation over ``period`` (each state's own draconitic period, scalar or ``(...)``)
    and :func:`average_qns`."""
    t = np.asarray(period, dtype=float)[..., None] * np.arange(samples) / samples
    states = propagate_rk4(x, t, substeps)
    return average_qns(oe_to_qns(eci_to_oe(states[..., :3], states[..., 3:])), t)


@dataclass(frozen=True)
class MeanOscMap:
    """First-order map between osculating and mean elements about reference states."""

    x_ref: FloatArray  # (N, 6) ECI states of the reference (the target at the nodes) [m, m/s]
    o_ref: FloatArray  # (N, 6) their osculating qns
    m_ref: FloatArray  # (N, 6) their mean qns
    J: FloatArray  # (N, 6, 6) dm/do at o_ref

    def take(self, index) -> MeanOscMap:
        """The map about a subset of the reference states."""
        return MeanOscMap(*(v[index] for v in (self.x_ref, self.o_ref, self.m_ref, self.J)))


def mean_osc_map(x_ref: FloatArray, period: float, samples: int = 48) -> MeanOscMap:
    """:class:`MeanOscMap` about the ECI states ``x_ref`` ``(N, 6)`` whose draconitic period is
    ``period``: ``dm/do`` by central differences of :func:`osculating_to_mean_qns` (13
    averaged orbits per state, batched; ~0.5 s for N = 100). Each probe is averaged over its
    own period (``period`` scaled by ``(a / a_ref)^(3/2)``): the window length is part of the
    definition of the mean elements, and its derivative w.r.t. ``a`` is not negligible (the
    short-period terms of ``a`` reach kilometres).
    """
    o_ref = oe_to_qns(eci_to_oe(x_ref[:, :3], x_ref[:, 3:]))
    probes = np.concatenate([np.zeros((1, 6)), np.diag(_STEPS), -np.diag(_STEPS)])  # (13, 6)
    o = o_ref[:, None, :] + probes
    r, v = oe_to_eci(qns_to_oe(o))
    periods = period * (o[..., 0] / o_ref[:, None, 0]) ** 1.5  # (N, 13)
    means = osculating_to_mean_qns(np.concatenate([r, v], axis=-1), periods, samples)
    J = qns_difference(means[:, 1:7], means[:, 7:13]) / (2.0 * _STEPS[None, :, None])
    return MeanOscMap(x_ref=x_ref, o_ref=o_ref, m_ref=means[:, 0], J=np.swapaxes(J, -1, -2))


def impulse_mean_qns(mo: MeanOscMap, m: FloatArray, dv_rtn: FloatArray) -> FloatArray:
    """Mean elements after an impulse, from the mean elements ``m`` before it.

    Osculating state before: ``o = o_ref + J^{-1} (m - m_ref)``; the impulse ``dv_rtn`` [m/s],
    in the spacecraft's own RTN frame, is added to its ECI velocity (exact two-body); the mean
    elements after are ``m + J (o+ - o)``. ``m`` ``(N, ..., 6)`` and ``dv_rtn`` ``(N, ..., 3)``
    share the leading node axis of ``mo``; the map is first order in ``m - m_ref`` (J2 times
    the squared separation, centimetres at kilometres) and exact in the impulse otherwise.
    """
    extra = m.ndim - 2
    o_ref, m_ref, J = (v.reshape(v.shape[0], *([1] * extra), *v.shape[1:])
                       for v in (mo.o_ref, mo.m_ref, mo.J))  # fmt: skip
    o = o_ref + np.linalg.solve(J, qns_difference(m, m_ref)[..., None])[..., 0]
    r, v = oe_to_eci(qns_to_oe(o))
    v_plus = v + np.einsum("...ji,...j->...i", rtn_dcm(r, v), dv_rtn)
    o_plus = oe_to_qns(eci_to_oe(r, v_plus))
    return m + np.einsum("...ij,...j->...i", J, qns_difference(o_plus, o))


def impulse_roe(mo: MeanOscMap, oe_chief: FloatArray, roe: FloatArray, dv_rtn: FloatArray):
    """Dimensionless MEAN ROE after impulses on the deputy (:func:`impulse_mean_qns`).

    ``oe_chief`` ``(N, 6)``: the chief's mean classical elements at the impulse times (the
    chief is not affected); ``roe`` ``(N, ..., 6)`` and ``dv_rtn`` ``(N, ..., 3)`` [m/s] in
    the deputy's RTN frame. Returns ``(N, ..., 6)``.
    """
    extra = roe.ndim - 2
    qc = oe_to_qns(oe_chief).reshape(oe_chief.shape[0], *([1] * extra), 6)
    m_plus = impulse_mean_qns(mo, qc + roe_to_qns_offset(qc, roe), dv_rtn)
    return qns_offset_to_roe(qc, m_plus - qc)


def impulse_roe_jacobian(
    mo: MeanOscMap, oe_chief: FloatArray, roe: FloatArray, dv_rtn: FloatArray,
    step_roe: float = 1e-7, step_dv: float = 1e-4,
) -> tuple[FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """:func:`impulse_roe` at ``(roe, dv)`` ``(N, 6), (N, 3)`` and its Jacobians ``(N, 6, 6)``
    w.r.t. ``roe`` and ``(N, 6, 3)`` w.r.t. ``dv`` [s/m], by central differences (steps
    ``step_roe``, 0.7 m at LEO, and ``step_dv`` [m/s]; the map is smooth, the errors are
    second order in the steps), all 19 evaluations in one batch."""
    eye6, eye3 = np.eye(6), np.eye(3)
    p_roe = np.concatenate([np.zeros((1, 6)), step_roe * eye6, -step_roe * eye6,
                            np.zeros((6, 6))])  # fmt: skip
    p_dv = np.concatenate([np.zeros((13, 3)), step_dv * eye3, -step_dv * eye3])
    out = impulse_roe(mo, oe_chief, roe[:, None, :] + p_roe, dv_rtn[:, None, :] + p_dv)
    d_roe = (out[:, 1:7] - out[:, 7:13]) / (2.0 * step_roe)  # (N, column, row)
    d_dv = (out[:, 13:16] - out[:, 16:19]) / (2.0 * step_dv)
    return out[:, 0], np.swapaxes(d_roe, 1, 2), np.swapaxes(d_dv, 1, 2)


def rtn_to_mean_roe(mo: MeanOscMap, rtn: FloatArray) -> FloatArray:
    """Dimensionless MEAN ROE ``(N, 6)`` of deputies whose OSCULATING relative state in the
    reference's RTN frame is ``rtn`` ``(N, 6)`` [m, m/s]: deputy ECI state (exact), its
    osculating elements, mean elements ``m_ref + J (o - o_ref)``, ROE w.r.t. the reference's
    mean elements. The inverse, to first order in J2 times the separation, of what a truth
    propagation started from the consistent osculating state shows."""
    r_d, v_d = rtn_to_eci(mo.x_ref[:, :3], mo.x_ref[:, 3:], rtn)
    o = oe_to_qns(eci_to_oe(r_d, v_d))
    diff = np.einsum("nij,nj->ni", mo.J, qns_difference(o, mo.o_ref))
    return qns_offset_to_roe(mo.m_ref, diff)
