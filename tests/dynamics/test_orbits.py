"""Tests of scpformer.dynamics.orbits (Kepler, elements <-> ECI, RTN frames, J2)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scpformer.dynamics.orbits import (
    J2,
    MU_EARTH,
    R_EARTH,
    OrbitalElements,
    accel_two_body_j2,
    eci_to_oe,
    eci_to_rtn,
    j2_secular_rates,
    mean_motion,
    mean_to_true,
    oe_to_eci,
    oe_to_qns,
    orbital_period,
    propagate_kepler,
    propagate_mean_j2,
    qns_to_oe,
    rtn_to_eci,
    solve_kepler,
    true_to_mean,
    validate_oe,
    wrap_to_pi,
)

# ISS-like target orbit of the ART paper, Table 1.
ISS = OrbitalElements.from_degrees(R_EARTH + 416e3, 5.58e-4, 51.64, 301.04, 26.18, 68.23)


def _random_oe(rng: np.random.Generator, k: int, e_max: float = 0.7) -> np.ndarray:
    e = rng.uniform(0.0, e_max, k)
    a = (R_EARTH + 200e3) / (1.0 - e) * rng.uniform(1.0, 3.0, k)  # perigee above 200 km
    return np.stack(
        [
            a,
            e,
            rng.uniform(0.01, np.pi - 0.01, k),
            rng.uniform(0, 2 * np.pi, k),
            rng.uniform(0, 2 * np.pi, k),
            rng.uniform(0, 2 * np.pi, k),
        ],
        axis=-1,
    )


def _angle_diff(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.abs(wrap_to_pi(np.asarray(x) - np.asarray(y)))


# ---------------------------------------------------------------------------------------
# Kepler's equation and anomalies
# ---------------------------------------------------------------------------------------
def test_kepler_solver_satisfies_keplers_equation_for_all_eccentricities():
    e = np.linspace(0.0, 0.99, 100)[:, None]
    M = np.linspace(-3 * np.pi, 3 * np.pi, 301)[None, :]
    E = solve_kepler(M, e)
    assert E.shape == (100, 301)
    np.testing.assert_allclose(E - e * np.sin(E), np.broadcast_to(M, E.shape), atol=1e-12)


def test_kepler_solver_keeps_the_revolution_count_of_the_mean_anomaly():
    E = solve_kepler(10.0 * np.pi + 0.3, 0.2)
    assert abs(E - (10.0 * np.pi + 0.3)) < 0.2 + 1e-12


def test_mean_true_anomaly_conversions_are_inverse():
    e = 0.3
    M = np.linspace(-np.pi + 1e-3, np.pi - 1e-3, 50)
    np.testing.assert_allclose(true_to_mean(mean_to_true(M, e), e), M, atol=1e-12)


# ---------------------------------------------------------------------------------------
# elements <-> ECI
# ---------------------------------------------------------------------------------------
def test_oe_to_eci_round_trip_recovers_the_elements():
    oe = _random_oe(np.random.default_rng(1), 200)
    r, v = oe_to_eci(oe)
    back = eci_to_oe(r, v)
    np.testing.assert_allclose(back[:, 0], oe[:, 0], rtol=1e-12)
    np.testing.assert_allclose(back[:, 1:3], oe[:, 1:3], atol=1e-12)
    assert np.max(_angle_diff(back[:, 3:], oe[:, 3:])) < 1e-9


def test_oe_to_eci_gives_vis_viva_energy_and_angular_momentum():
    oe = _random_oe(np.random.default_rng(2), 50)
    r, v = oe_to_eci(oe)
    a, e = oe[:, 0], oe[:, 1]
    energy = 0.5 * np.sum(v * v, axis=1) - MU_EARTH / np.linalg.norm(r, axis=1)
    np.testing.assert_allclose(energy, -MU_EARTH / (2 * a), rtol=1e-12)
    h = np.linalg.norm(np.cross(r, v), axis=1)
    np.testing.assert_allclose(h, np.sqrt(MU_EARTH * a * (1 - e**2)), rtol=1e-12)


def test_oe_to_eci_places_a_circular_equatorial_orbit_on_the_x_axis_at_zero_anomaly():
    r, v = oe_to_eci([7000e3, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(r, [7000e3, 0, 0], atol=1e-6)
    np.testing.assert_allclose(v, [0, np.sqrt(MU_EARTH / 7000e3), 0], atol=1e-9)


def test_near_circular_round_trip_preserves_the_mean_argument_of_latitude():
    for e in (0.0, 1e-12, 5.58e-4):
        oe = ISS.to_array()
        oe[1] = e
        back = eci_to_oe(*oe_to_eci(oe))
        assert _angle_diff(back[4] + back[5], oe[4] + oe[5]) < 1e-10
        assert abs(back[1] - e) < 1e-12


def test_quasi_nonsingular_elements_round_trip():
    oe = _random_oe(np.random.default_rng(3), 20)
    back = qns_to_oe(oe_to_qns(oe))
    np.testing.assert_allclose(back[:, :3], oe[:, :3], rtol=1e-12)
    assert np.max(_angle_diff(back[:, 3:], oe[:, 3:])) < 1e-12


# ---------------------------------------------------------------------------------------
# RTN frame
# ---------------------------------------------------------------------------------------
def test_rtn_and_eci_relative_state_conversions_are_inverse():
    r_c, v_c = oe_to_eci(ISS.to_array())
    rtn = np.random.default_rng(4).normal(size=(10, 6)) * [100, 100, 100, 0.1, 0.1, 0.1]
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn)
    np.testing.assert_allclose(eci_to_rtn(r_c, v_c, r_d, v_d), rtn, atol=1e-8)


def test_rtn_velocity_is_the_time_derivative_of_rtn_position_in_two_body_motion():
    oe_c = ISS.to_array()
    oe_d = oe_c + np.array([50.0, 1e-4, 1e-5, 2e-5, 0.0, 1e-5])
    t = np.array([-0.5, 0.5])
    states = [oe_to_eci(propagate_kepler(o, t)) for o in (oe_c, oe_d)]
    rtn = eci_to_rtn(*states[0], *states[1])
    mid = eci_to_rtn(*oe_to_eci(oe_c), *oe_to_eci(oe_d))
    np.testing.assert_allclose(rtn[1, :3] - rtn[0, :3], mid[3:], rtol=1e-6, atol=1e-9)


# ---------------------------------------------------------------------------------------
# mean motion, J2
# ---------------------------------------------------------------------------------------
def test_iss_orbit_period_matches_table_1_of_the_art_paper():
    assert orbital_period(ISS.a) / 3600.0 == pytest.approx(1.548, abs=1e-3)
    assert ISS.period == pytest.approx(float(orbital_period(ISS.a)))
    assert ISS.mean_motion == pytest.approx(float(mean_motion(ISS.a)))


def test_j2_nodal_regression_of_the_iss_is_about_minus_five_degrees_per_day():
    raan_dot, argp_dot, M_dot = j2_secular_rates(ISS.to_array())
    per_day = np.rad2deg(86400.0)
    assert -5.1 < raan_dot * per_day < -4.9
    assert 3.5 < argp_dot * per_day < 3.9  # 5 cos^2 i - 1 > 0 below 63.4 deg
    assert M_dot > ISS.mean_motion


def test_j2_apsidal_rate_vanishes_at_the_critical_inclination():
    oe = ISS.to_array()
    oe[2] = np.arccos(np.sqrt(1 / 5))
    assert abs(j2_secular_rates(oe)[1]) < 1e-20


def test_j2_acceleration_is_the_gradient_of_the_j2_potential():
    def potential(r):
        rn = np.linalg.norm(r)
        return MU_EARTH / rn * (1 - J2 * (R_EARTH / rn) ** 2 * (1.5 * (r[2] / rn) ** 2 - 0.5))

    r = np.array([3000e3, -4500e3, 4200e3])
    h = 1.0
    grad = np.array([(potential(r + h * ei) - potential(r - h * ei)) / (2 * h) for ei in np.eye(3)])
    np.testing.assert_allclose(accel_two_body_j2(r), grad, rtol=1e-7)
    batch = accel_two_body_j2(np.stack([r, 2 * r]))
    np.testing.assert_allclose(batch[0], accel_two_body_j2(r), rtol=1e-15)


def test_propagators_broadcast_over_a_time_grid():
    t = np.linspace(0, 3 * ISS.period, 7)
    kep = propagate_kepler(ISS.to_array(), t)
    j2 = propagate_mean_j2(ISS.to_array(), t)
    assert kep.shape == j2.shape == (7, 6)
    assert _angle_diff(kep[-1, 5], ISS.M) < 1e-9  # three full revolutions
    np.testing.assert_allclose(kep[:, :5], np.broadcast_to(ISS.to_array()[:5], (7, 5)))
    raan_dot = j2_secular_rates(ISS.to_array())[0]
    assert _angle_diff(j2[-1, 3], ISS.raan + raan_dot * t[-1]) < 1e-12


# ---------------------------------------------------------------------------------------
# dataclass and validation
# ---------------------------------------------------------------------------------------
def test_orbital_elements_from_degrees_converts_angles_and_is_frozen():
    assert ISS.i == pytest.approx(np.deg2rad(51.64))
    np.testing.assert_allclose(
        OrbitalElements.from_array(ISS.to_array()).to_array(), ISS.to_array()
    )
    with pytest.raises(dataclasses.FrozenInstanceError):
        ISS.a = 7e6  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        (dict(a=R_EARTH - 1.0), r"\ba\b"),
        (dict(e=1.0), r"\be\b"),
        (dict(e=-0.1), r"\be\b"),
        (dict(i=4.0), r"\bi\b"),
        (dict(raan=np.nan), "raan"),
        (dict(M=np.inf), r"\bM\b"),
        (
            dict(a=np.array([7e6, 8e6])),
            r"a: expected a real number, got \[7000000\.0, 8000000\.0\]",
        ),
    ],
)
def test_orbital_elements_reject_non_physical_values_naming_the_field(kwargs, field):
    fields = dict(a=7e6, e=0.01, i=0.9, raan=0.1, argp=0.2, M=0.3)
    fields.update(kwargs)
    with pytest.raises(ValueError, match=field):
        OrbitalElements(**fields)


def test_validate_oe_rejects_wrong_shapes_and_bad_fields():
    with pytest.raises(ValueError, match=r"oe: expected shape \(\.\.\., 6\)"):
        validate_oe(np.zeros(5))
    with pytest.raises(ValueError, match=r"oe\.e"):
        validate_oe([[7e6, 0.01, 0.9, 0, 0, 0], [7e6, 1.5, 0.9, 0, 0, 0]])
    with pytest.raises(ValueError, match=r"oe\.a"):
        oe_to_eci([1e6, 0.01, 0.9, 0, 0, 0])


def test_eci_to_oe_rejects_unbound_and_malformed_states():
    r, v = oe_to_eci(ISS.to_array())
    with pytest.raises(ValueError, match="unbound"):
        eci_to_oe(r, 2.0 * v)
    with pytest.raises(ValueError, match=r"r: expected shape"):
        eci_to_oe(r[:2], v)
    with pytest.raises(ValueError, match="v: contains NaN"):
        eci_to_oe(r, v * np.nan)


def test_kepler_solver_rejects_non_elliptic_eccentricity():
    with pytest.raises(ValueError, match="e:"):
        solve_kepler(1.0, 1.0)
    with pytest.raises(ValueError, match="a:"):
        mean_motion(-1.0)
