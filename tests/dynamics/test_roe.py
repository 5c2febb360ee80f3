"""Tests of scpformer.dynamics.roe: exact maps, Psi, B, and the ROE STMs."""

from __future__ import annotations

import numpy as np
import pytest

from scpformer.dynamics.orbits import (
    R_EARTH,
    OrbitalElements,
    eci_to_oe,
    oe_to_eci,
    oe_to_qns,
    propagate_mean_j2,
    propagate_mean_qns,
    rtn_dcm,
    wrap_to_pi,
)
from scpformer.dynamics.roe import (
    control_input_matrix,
    oe_to_roe,
    propagate_roe_mean,
    psi_matrix,
    roe_flow_jacobian,
    roe_to_oe,
    roe_to_rtn_exact,
    rtn_dv_to_roe,
    rtn_to_roe_exact,
    scale_roe,
    stm_j2,
    stm_kepler,
    unscale_roe,
)

# ISS-like target orbit of the ART paper, Table 1.
ISS = OrbitalElements.from_degrees(R_EARTH + 416e3, 5.58e-4, 51.64, 301.04, 26.18, 68.23)
# A markedly eccentric orbit (perigee ~ 820 km) to exercise the eccentric forms.
ECC = OrbitalElements.from_degrees(8000e3, 0.1, 51.64, 301.04, 26.18, 68.23)
RNG_DIRS = np.random.default_rng(0).normal(size=(20, 6))
DIRS = RNG_DIRS / np.linalg.norm(RNG_DIRS, axis=1, keepdims=True)


def _chief_at(oe: OrbitalElements, M: float) -> np.ndarray:
    c = oe.to_array()
    c[5] = M
    return c


# ---------------------------------------------------------------------------------------
# exact maps
# ---------------------------------------------------------------------------------------
def test_roe_to_oe_and_oe_to_roe_are_inverse():
    c = ISS.to_array()
    roe = 1e-4 * DIRS  # ~700 m separations
    d = roe_to_oe(c, roe)
    assert d.shape == (20, 6)
    np.testing.assert_allclose(oe_to_roe(c, d), roe, atol=1e-14)
    back = roe_to_oe(c, oe_to_roe(c, d))
    np.testing.assert_allclose(back[:, :3], d[:, :3], rtol=1e-13)
    assert np.max(np.abs(wrap_to_pi(back[:, 3:] - d[:, 3:]))) < 1e-10


def test_oe_to_roe_follows_the_quasi_nonsingular_definition():
    c = ISS.to_array()
    d = c.copy()
    d[3] += 1e-4  # raan only
    roe = oe_to_roe(c, d)
    np.testing.assert_allclose(
        roe, [0, 1e-4 * np.cos(c[2]), 0, 0, 0, 1e-4 * np.sin(c[2])], atol=1e-15
    )
    d = c.copy()
    d[0] += 70.0
    d[2] += 2e-5
    d[1] = 0.0
    roe = oe_to_roe(c, d)
    np.testing.assert_allclose(roe[0], 70.0 / c[0], rtol=1e-12)
    np.testing.assert_allclose(roe[2:5], [-c[1] * np.cos(c[4]), -c[1] * np.sin(c[4]), 2e-5])


def test_relative_mean_longitude_is_wrapped_across_two_pi():
    c = np.array([7e6, 0.0, 0.9, 0.0, 0.0, np.deg2rad(359.0)])
    d = c.copy()
    d[5] = np.deg2rad(1.0)
    assert oe_to_roe(c, d)[1] == pytest.approx(np.deg2rad(2.0))


def test_scaled_roe_helpers_are_inverse():
    roe = 1e-5 * DIRS
    aroe = scale_roe(ISS, roe)
    np.testing.assert_allclose(aroe, ISS.a * roe)
    np.testing.assert_allclose(unscale_roe(ISS, aroe), roe, rtol=1e-15)


def test_exact_rtn_and_roe_maps_are_inverse():
    for oe in (ISS, ECC):
        roe = 3e-4 * DIRS
        rtn = roe_to_rtn_exact(oe, roe)
        np.testing.assert_allclose(rtn_to_roe_exact(oe, rtn), roe, atol=1e-13)


# ---------------------------------------------------------------------------------------
# Psi
# ---------------------------------------------------------------------------------------
def _psi_relative_errors(oe: OrbitalElements, sep: float, model: str) -> tuple[float, float]:
    """Worst relative error of Psi @ aroe vs the exact map over 12 anomalies x 20 directions."""
    err_p = err_v = 0.0
    for M in np.linspace(0, 2 * np.pi, 12, endpoint=False):
        c = _chief_at(oe, M)
        aroe = sep * DIRS
        exact = roe_to_rtn_exact(c, aroe / c[0])
        lin = aroe @ psi_matrix(c, model).T
        err_p = max(
            err_p,
            np.max(
                np.linalg.norm((lin - exact)[:, :3], axis=1) / np.linalg.norm(exact[:, :3], axis=1)
            ),
        )
        err_v = max(
            err_v,
            np.max(
                np.linalg.norm((lin - exact)[:, 3:], axis=1) / np.linalg.norm(exact[:, 3:], axis=1)
            ),
        )
    return err_p, err_v


@pytest.mark.parametrize("oe", [ISS, ECC], ids=["iss", "e0.1"])
def test_eccentric_psi_matches_the_exact_map_with_second_order_error(oe):
    """Psi is first order, so its error relative to the separation is O(separation / a).

    Measured (ISS and e = 0.1, worst over anomalies and ROE directions): relative error of
    RTN position and velocity 3.1e-6 at 10 m, 3.1e-5 at 100 m, 3.1e-4 at 1 km, i.e.
    about 2 |a delta_alpha| / a. We assert < 6e-5 at 100 m and the tenfold decrease from
    100 m to 10 m (the signature of a correct first-order map; a wrong entry would give an
    O(1) error that does not decrease).
    """
    p100, v100 = _psi_relative_errors(oe, 100.0, "eccentric")
    p10, v10 = _psi_relative_errors(oe, 10.0, "eccentric")
    assert p100 < 6e-5 and v100 < 6e-5
    assert p10 < 0.15 * p100 and v10 < 0.15 * v100


def test_near_circular_psi_errs_by_order_e_and_equals_the_eccentric_one_for_e_zero():
    """The near-circular Psi neglects O(e): measured relative error 4.5e-3 for the ISS
    (e = 5.6e-4, about 8 e), 0.6 for e = 0.1, against 3e-5 for the eccentric map at 100 m."""
    p_iss, _ = _psi_relative_errors(ISS, 100.0, "near_circular")
    p_ecc, _ = _psi_relative_errors(ECC, 100.0, "near_circular")
    assert 1e-3 < p_iss < 1e-2
    assert p_ecc > 0.1
    c = ISS.to_array()
    c[1] = 0.0
    np.testing.assert_allclose(psi_matrix(c), psi_matrix(c, "near_circular"), atol=1e-15)


def test_psi_is_the_jacobian_of_the_exact_map():
    for oe in (ISS, ECC):
        c = oe.to_array()
        h = 1.0  # metres of scaled ROE; central differences are O(h^2 / a^2)
        J = np.empty((6, 6))
        for j in range(6):
            d = np.zeros(6)
            d[j] = h / c[0]
            J[:, j] = (roe_to_rtn_exact(c, d) - roe_to_rtn_exact(c, -d)) / (2 * h)
        P = psi_matrix(c)
        scale = np.abs(P).max(axis=1, keepdims=True)
        assert np.max(np.abs(J - P) / scale) < 1e-8


def test_psi_is_vectorized_over_chief_states():
    chiefs = np.stack([_chief_at(ECC, M) for M in np.linspace(0, 6, 5)])
    P = psi_matrix(chiefs)
    assert P.shape == (5, 6, 6)
    np.testing.assert_allclose(P[3], psi_matrix(chiefs[3]), rtol=1e-15)


# ---------------------------------------------------------------------------------------
# B
# ---------------------------------------------------------------------------------------
def _b_finite_difference(c: np.ndarray, dv_mag: float = 1e-3) -> np.ndarray:
    """Apply +-dv along each RTN axis to the deputy (co-located with the chief) velocity."""
    r, v = oe_to_eci(c)
    C = rtn_dcm(r, v)
    J = np.empty((6, 3))
    for j in range(3):
        dv = C.T @ (dv_mag * np.eye(3)[j])
        plus = oe_to_roe(c, eci_to_oe(r, v + dv))
        minus = oe_to_roe(c, eci_to_oe(r, v - dv))
        J[:, j] = c[0] * (plus - minus) / (2 * dv_mag)
    return J


@pytest.mark.parametrize("oe", [ISS, ECC], ids=["iss", "e0.1"])
def test_control_input_matrix_matches_finite_differences_of_the_exact_map(oe):
    """Gauss variational equations vs central differences with 1 mm/s impulses: measured
    agreement ~1e-8 relative to the largest entry (limited by round-off in the ROE)."""
    for M in np.linspace(0, 2 * np.pi, 7, endpoint=False):
        c = _chief_at(oe, M)
        B = control_input_matrix(c)
        fd = _b_finite_difference(c)
        assert np.max(np.abs(B - fd)) < 1e-6 * np.max(np.abs(B))


def test_near_circular_control_input_matrix_is_exact_for_circular_orbits_only():
    c = ISS.to_array()
    c[1] = 0.0
    B = control_input_matrix(c, "near_circular")
    np.testing.assert_allclose(B, control_input_matrix(c), atol=1e-12 * np.abs(B).max())
    np.testing.assert_allclose(B, _b_finite_difference(c), atol=1e-6 * np.abs(B).max())
    ecc = ECC.to_array()
    err = np.abs(control_input_matrix(ecc, "near_circular") - _b_finite_difference(ecc))
    assert err.max() > 0.05 * np.abs(control_input_matrix(ecc)).max()


def test_tangential_impulse_raises_the_scaled_semi_major_axis_by_two_over_n():
    c = ISS.to_array()
    c[1] = 0.0
    d_aroe = rtn_dv_to_roe(c, [0.0, 0.01, 0.0])
    assert d_aroe[0] == pytest.approx(2 * 0.01 / ISS.mean_motion, rel=1e-12)


def test_rtn_dv_to_roe_is_vectorized_over_impulses_and_chief_states():
    chiefs = np.stack([_chief_at(ISS, M) for M in np.linspace(0, 6, 4)])
    dv = np.random.default_rng(5).normal(size=(4, 3)) * 0.01
    out = rtn_dv_to_roe(chiefs, dv)
    assert out.shape == (4, 6)
    np.testing.assert_allclose(out[2], control_input_matrix(chiefs[2]) @ dv[2], rtol=1e-14)
    assert control_input_matrix(chiefs).shape == (4, 6, 3)


# ---------------------------------------------------------------------------------------
# STMs
# ---------------------------------------------------------------------------------------
def _secular_jacobian(c: np.ndarray, dt: float, h: float = 1e-7) -> np.ndarray:
    """Central-difference Jacobian of the mean ROE after dt under secular J2 drift."""
    cf = propagate_mean_j2(c, dt)
    J = np.empty((6, 6))
    for j in range(6):
        d = np.zeros(6)
        d[j] = h
        plus = oe_to_roe(cf, propagate_mean_j2(roe_to_oe(c, d), dt))
        minus = oe_to_roe(cf, propagate_mean_j2(roe_to_oe(c, -d), dt))
        J[:, j] = (plus - minus) / (2 * h)
    return J


@pytest.mark.parametrize("oe", [ISS, ECC], ids=["iss", "e0.1"])
def test_j2_stm_is_the_jacobian_of_the_secular_j2_mean_element_drift(oe):
    """Koenig et al. (2017) QNS J2 STM vs the numerical Jacobian of first-order secular J2
    propagation of both spacecraft: measured agreement ~2e-8 (finite-difference error),
    over 1 to 10 orbits, while the entries themselves reach 60 (the -3/2 n dt term)."""
    c = oe.to_array()
    for n_orb in (1.0, 3.0, 10.0):
        dt = n_orb * oe.period
        assert np.max(np.abs(stm_j2(c, dt) - _secular_jacobian(c, dt))) < 1e-6


@pytest.mark.parametrize("oe", [ISS, ECC], ids=["iss", "e0.1"])
def test_nonsingular_mean_propagation_equals_the_classical_one(oe):
    c = oe.to_array()
    dt = np.array([0.0, 600.0, 3.0 * oe.period])
    q = propagate_mean_qns(oe_to_qns(c), dt)
    ref = oe_to_qns(propagate_mean_j2(c, dt))
    np.testing.assert_allclose(q[:, [0, 2, 3, 4]], ref[:, [0, 2, 3, 4]], atol=1e-12, rtol=1e-13)
    np.testing.assert_allclose(wrap_to_pi(q[:, [1, 5]] - ref[:, [1, 5]]), 0.0, atol=1e-12)


def test_nonlinear_roe_flow_propagates_both_spacecraft_with_their_own_secular_rates():
    """Independent route: deputy elements, classical secular propagation, ROE again."""
    c = ISS.to_array()
    roe = DIRS[:5] * 5e3 / c[0]  # kilometres of separation
    dt = np.array([60.0, 0.5 * ISS.period, 2.0 * ISS.period, 3.0, 7.0 * ISS.period])
    ref = oe_to_roe(propagate_mean_j2(c, dt), propagate_mean_j2(roe_to_oe(c, roe), dt))
    np.testing.assert_allclose(propagate_roe_mean(c, roe, dt) * c[0], ref * c[0], atol=1e-6)


def test_nonlinear_roe_flow_differs_from_the_stm_by_the_second_order_along_track_drift():
    """At a da = -5 km the STM misses 15/8 n a da^2 t of a dlambda (~44 m per orbit)."""
    c = ISS.to_array()
    a = c[0]
    roe = np.array([-5e3, 2e3, 0.0, 0.0, 0.0, 0.0]) / a
    T = ISS.period
    err = (propagate_roe_mean(c, roe, T) - stm_j2(c, T) @ roe) * a
    expected = 15.0 / 8.0 * 2.0 * np.pi * (5e3) ** 2 / a
    assert err[1] == pytest.approx(expected, rel=0.02)
    assert np.all(np.abs(err[[0, 2, 3, 4]]) < 1e-3)


@pytest.mark.parametrize("oe", [ISS, ECC], ids=["iss", "e0.1"])
def test_roe_flow_jacobian_is_the_j2_stm_at_zero_separation(oe):
    c = oe.to_array()
    for dt in (60.0, oe.period, 5.0 * oe.period):
        flow, jac = roe_flow_jacobian(c, np.zeros(6), dt)
        np.testing.assert_allclose(flow, 0.0, atol=1e-15)
        assert np.max(np.abs(jac - stm_j2(c, dt))) < 1e-6


def test_roe_flow_jacobian_predicts_small_steps_at_kilometre_separations():
    """First-order prediction of a 20 m step from a -5 km reference is right to micrometres
    (the STM about the chief is off by metres there)."""
    c = ISS.to_array()
    a = c[0]
    y = np.array([-5e3, 8e3, 300.0, -200.0, 100.0, 150.0]) / a
    dt = np.array([70.0, ISS.period])
    flow, jac = roe_flow_jacobian(c, y, dt)
    step = DIRS[0] * 20.0 / a
    pred = flow + np.einsum("kij,j->ki", jac, step)
    np.testing.assert_allclose(propagate_roe_mean(c, y + step, dt) * a, pred * a, atol=1e-4)
    assert np.max(np.abs(jac[1] - stm_j2(c, dt[1]))) * 20.0 > 1e-3


def test_j2_stm_reduces_to_the_keplerian_stm_without_j2():
    c = ISS.to_array()
    dt = np.linspace(0, 3 * ISS.period, 4)
    np.testing.assert_allclose(stm_j2(c, dt, j2=0.0), stm_kepler(c, dt), atol=1e-15)
    assert stm_kepler(c, 100.0)[1, 0] == pytest.approx(-1.5 * ISS.mean_motion * 100.0)
    assert np.max(np.abs(stm_j2(c, dt[-1]) - stm_kepler(c, dt[-1]))) > 1e-3


def test_j2_stm_composes_along_the_mean_chief_orbit():
    c = ECC.to_array()
    t1, t2 = 0.7 * ECC.period, 1.9 * ECC.period
    c1 = propagate_mean_j2(c, t1)
    np.testing.assert_allclose(stm_j2(c1, t2) @ stm_j2(c, t1), stm_j2(c, t1 + t2), atol=1e-10)


def test_stms_are_vectorized_over_time_steps_and_chief_states():
    c = ISS.to_array()
    dt = np.linspace(0, 3 * ISS.period, 11)
    Phi = stm_j2(c, dt)
    assert Phi.shape == (11, 6, 6)
    np.testing.assert_allclose(Phi[7], stm_j2(c, dt[7]), rtol=1e-15)
    chiefs = propagate_mean_j2(c, dt)
    assert stm_j2(chiefs, 60.0).shape == (11, 6, 6)
    assert stm_j2(chiefs, np.full(11, 60.0)).shape == (11, 6, 6)
    assert stm_kepler(chiefs, dt).shape == (11, 6, 6)


# ---------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------
def test_bad_inputs_raise_value_errors_naming_the_argument():
    c = ISS.to_array()
    with pytest.raises(ValueError, match=r"roe: expected shape"):
        roe_to_oe(c, np.zeros(5))
    with pytest.raises(ValueError, match="roe: contains NaN"):
        roe_to_rtn_exact(c, [0, np.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match=r"oe_chief\.a"):
        psi_matrix([R_EARTH - 1, 0.0, 0.9, 0, 0, 0])
    with pytest.raises(ValueError, match=r"oe_chief\.e"):
        stm_j2([7e6, 1.2, 0.9, 0, 0, 0], 10.0)
    with pytest.raises(ValueError, match=r"oe_deputy\.e"):
        oe_to_roe(c, [7e6, -0.1, 0.9, 0, 0, 0])
    with pytest.raises(ValueError, match="dt: contains NaN"):
        stm_kepler(c, np.nan)
    with pytest.raises(ValueError, match="dv_rtn: expected shape"):
        rtn_dv_to_roe(c, [1.0, 2.0])
    with pytest.raises(ValueError, match="model"):
        psi_matrix(c, "circular")  # type: ignore[arg-type]


def test_roe_giving_an_unbound_or_subsurface_deputy_is_rejected():
    c = ISS.to_array()
    with pytest.raises(ValueError, match=r"deputy \(from roe\)\.e"):
        roe_to_oe(c, [0, 0, 1.5, 0, 0, 0])
    with pytest.raises(ValueError, match=r"deputy \(from roe\)\.a"):
        roe_to_oe(c, [-0.5, 0, 0, 0, 0, 0])


def test_equatorial_chief_is_rejected_where_the_roe_are_singular():
    eq = np.array([7e6, 0.01, 0.0, 0.0, 0.3, 0.2])
    with pytest.raises(ValueError, match=r"oe_chief\.i"):
        roe_to_oe(eq, [0, 0, 0, 0, 0, 1e-5])
    with pytest.raises(ValueError, match=r"oe_chief\.i"):
        psi_matrix(eq)
    assert np.all(np.isfinite(psi_matrix(eq, "near_circular")))
