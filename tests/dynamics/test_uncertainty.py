"""Tests of scpformer.dynamics.uncertainty: Eqs. 10-14 and 16 of the robust ART paper.

Monte Carlo tolerance
---------------------
Sample covariances are compared after whitening by the analytic covariance: with
``L L^T = X`` and ``n`` zero-mean samples ``e``, ``W = L^{-1} (e e^T / n) L^{-T}`` is
``Wishart(n, I) / n`` when ``X`` is right, so its diagonal entries have standard deviation
``sqrt(2/n)`` and its off-diagonal ones ``sqrt(1/n)``, in every direction of the state space
whatever the conditioning of ``X`` (it spans 1e-6 to 1e5 m^2 here). With ``n = 100_000``
the test allows ``|W - I| <= 5 sqrt(2/n) = 0.022``: a 3% error in the variance along any
direction fails it (checked by mutation: a 3% scaling of X, a wrong Gates pointing sigma or
a transposed STM all fail, the largest error of the correct model is 0.013), and a correct
implementation passes each of the ~500 entries checked with probability 1 - 6e-7 (5 sigma),
i.e. the whole test with probability > 0.999. The draws are seeded: the outcome is
reproducible.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import sqrtm
from scipy.stats import norm

from scpformer.dynamics.orbits import OrbitalElements, propagate_mean_j2
from scpformer.dynamics.roe import control_input_matrix, psi_matrix, stm_j2
from scpformer.dynamics.uncertainty import (
    GatesModel,
    NavigationModel,
    ProcessNoise,
    UncertaintyModel,
    burn_frame,
    chance_margin,
    confidence_quantile,
    covariance_history,
    propagate_covariance,
)

TARGET = OrbitalElements.from_degrees(6738e3, 5.58e-4, 51.64, 301.04, 26.18, 68.23)  # Table 1
N_MC = 100_000
MC_TOL = 5.0 * np.sqrt(2.0 / N_MC)
MODEL = UncertaintyModel()


@pytest.fixture(scope="module")
def horizon():
    """8 nodes over one target orbit, ranges spanning the three cases of Eq. 11, some coasts."""
    n_nodes = 8
    dt = TARGET.period / (n_nodes - 1)
    chief = propagate_mean_j2(TARGET.to_array(), dt * np.arange(n_nodes))
    along = np.array([-20e3, -12e3, -8e3, -5.5e3, -2e3, -1e3, -500.0, 0.0])
    x = np.zeros((n_nodes, 6))
    x[:, 1], x[:, 2], x[:, 5] = along, 0.1 * along, 50.0
    u = np.random.default_rng(1).normal(scale=0.2, size=(n_nodes, 3))
    u[[2, 5]] = 0.0
    return dict(
        chief=chief,
        x=x,
        u=u,
        stm=stm_j2(chief[:-1], dt),
        B=control_input_matrix(chief),
        psi=psi_matrix(chief),
    )


def _whitened_error(samples: np.ndarray, X: np.ndarray) -> float:
    """``max |L^-1 S L^-T - I|`` for samples (n, 6) of a zero-mean Gaussian with covariance X."""
    w = np.linalg.solve(np.linalg.cholesky(X), samples.T)
    return float(np.max(np.abs(w @ w.T / samples.shape[0] - np.eye(X.shape[0]))))


def _sample_node_errors(h: dict, i: int, rng: np.random.Generator) -> np.ndarray:
    """Errors right after the impulse at node i, drawn source by source (Eqs. 10-13)."""
    rho = np.linalg.norm((h["psi"][i] @ h["x"][i])[:3])
    sigma_nav = rho * MODEL.navigation.scale(rho)
    nav = rng.standard_normal((N_MC, 6)) * sigma_nav
    act = MODEL.actuation.sample(h["u"][i], rng, N_MC) @ h["B"][i].T
    proc = rng.standard_normal((N_MC, 6)) @ np.linalg.cholesky(MODEL.process_noise.matrix).T
    return nav + act + proc


def test_covariance_history_matches_monte_carlo_on_the_linear_model(horizon):
    h = horizon
    hist = covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"], MODEL)
    drift = stm_j2(h["chief"], TARGET.period)  # one free-drift orbit from every node
    rng = np.random.default_rng(2024)
    for i in range(len(h["x"])):
        e = _sample_node_errors(h, i, rng)
        assert _whitened_error(e, hist.X[i]) < MC_TOL
        if i < len(h["stm"]):
            assert _whitened_error(e @ h["stm"][i].T, hist.X_next[i]) < MC_TOL
        X_drift = propagate_covariance(hist.X[i], drift[i])
        assert _whitened_error(e @ drift[i].T, X_drift) < MC_TOL


def test_covariance_between_navigation_fixes_matches_the_chained_monte_carlo(horizon):
    """Fixes at nodes 0 and 3 and 6 of 8: at a fix the error is drawn as in Eq. 14; between
    fixes the plan flies open loop and the post-maneuver error is the previous one carried by
    the STM plus the node's Gates and process errors, sampled here source by source."""
    h, model = horizon, UncertaintyModel(fix_every=3)
    hist = covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"], model)
    rng = np.random.default_rng(2025)
    chol_q = np.linalg.cholesky(MODEL.process_noise.matrix)
    e = None
    for i in range(len(h["x"])):
        if i % 3 == 0:
            e = _sample_node_errors(h, i, rng)
        else:
            act = MODEL.actuation.sample(h["u"][i], rng, N_MC) @ h["B"][i].T
            e = e @ h["stm"][i - 1].T + act + rng.standard_normal((N_MC, 6)) @ chol_q.T
        assert _whitened_error(e, hist.X[i]) < MC_TOL, i
    fixes = np.arange(len(h["x"])) % 3 == 0
    assert not np.any(hist.X_carry[fixes]) and not np.any(hist.X_nav[~fixes])
    eq14 = covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"], MODEL)
    np.testing.assert_array_equal(hist.X[fixes], eq14.X[fixes])
    assert not np.any(eq14.X_carry)


def test_covariance_history_is_positive_definite_and_symmetric(horizon):
    h = horizon
    hist = covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"])
    drift = propagate_covariance(hist.X, stm_j2(h["chief"], 3.0 * TARGET.period))
    for X in (hist.X, hist.X_next, drift):
        assert np.array_equal(X, np.swapaxes(X, -1, -2))
        assert np.all(np.linalg.eigvalsh(X)[:, 0] > 0.0)
        np.linalg.cholesky(X)  # raises if not positive definite


def test_covariance_at_the_target_without_burn_is_fixed_errors_plus_process_noise(horizon):
    h = horizon
    zeros = np.zeros((1, 3))
    hist = covariance_history(np.zeros((1, 6)), zeros, h["stm"][:0], h["B"][:1], h["psi"][:1])
    B = h["B"][0]
    expected = 3e-4**2 * B @ B.T + 1e-6 * np.eye(6)  # sigma_r = sigma_a, rho = 0
    np.testing.assert_allclose(hist.X[0], expected, rtol=1e-12)
    assert hist.rho[0] == 0.0 and not np.any(hist.X_nav)


def test_navigation_scale_interpolates_eq_11():
    nav = NavigationModel()
    s1, s2 = np.array(nav.s1), np.array(nav.s2)
    s = nav.scale([20e3, 10e3, 5.5e3, 1e3, 200.0])
    np.testing.assert_allclose(s, [s1, s1, 0.5 * (s1 + s2), s2, s2], rtol=1e-12)


def test_navigation_covariance_is_diagonal_with_range_times_s():
    nav = NavigationModel()
    X = nav.covariance([3e3, 15e3])
    sigma = np.array([3e3, 15e3])[:, None] * nav.scale([3e3, 15e3])
    np.testing.assert_allclose(X, np.einsum("ki,ij->kij", sigma**2, np.eye(6)), rtol=1e-12)


@pytest.mark.parametrize(
    "dv", [[0.3, -0.1, 0.05], [0.0, 2.0, 0.0], [0.0, 0.0, -1e-3], [0.0, 0.0, 0.0]]
)
def test_gates_covariance_is_R_V_R_transpose(dv):
    g = GatesModel(sigma_s=2e-3, sigma_p=3e-4, sigma_r=5e-4, sigma_a=1e-4)
    R = burn_frame(dv)
    v2 = float(np.dot(dv, dv))
    V = np.diag(
        [
            g.sigma_r**2 + v2 * g.sigma_s**2,
            g.sigma_a**2 + v2 * g.sigma_p**2,
            g.sigma_a**2 + v2 * g.sigma_p**2,
        ]
    )
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(g.covariance(dv), R @ V @ R.T, rtol=1e-12, atol=1e-22)


def test_gates_covariance_is_vectorized_and_matches_burn_frame_samples():
    g = GatesModel()
    dv = np.array([[0.5, 0.2, -0.1], [0.0, 0.0, 0.0], [-3.0, 0.0, 0.0]])
    U = g.covariance(dv)
    np.testing.assert_allclose(U[1], 3e-4**2 * np.eye(3), rtol=1e-12)
    samples = g.sample(dv, np.random.default_rng(5), N_MC)  # (n, 3, 3)
    for k in range(3):
        assert _whitened_error(samples[:, k], U[k]) < MC_TOL


def test_quantile_is_one_sided_normal_ppf_and_gives_table_2_value():
    q = confidence_quantile(1e-3)
    assert round(q, 2) == 3.09
    assert q == pytest.approx(norm.ppf(1.0 - 1e-3), rel=1e-12)
    assert norm.sf(q) == pytest.approx(1e-3, rel=1e-12)
    assert MODEL.q == q


def test_margin_vanishes_with_zero_covariance():
    a = np.random.default_rng(0).normal(size=(5, 6))
    np.testing.assert_array_equal(chance_margin(np.zeros((5, 6, 6)), a), np.zeros(5))


def test_margin_is_q_times_norm_of_sqrt_covariance_times_a(horizon):
    h = horizon
    X = covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"]).X
    a = np.random.default_rng(3).normal(size=(len(X), 6))
    root = np.real(np.stack([sqrtm(Xi) for Xi in X]))  # symmetric square roots X^(1/2)
    expected = 3.0902323 * np.linalg.norm(np.einsum("kij,kj->ki", root, a), axis=-1)
    np.testing.assert_allclose(chance_margin(X, a, 1e-3), expected, rtol=1e-6)


def test_margin_is_exceeded_with_probability_delta():
    """P(a^T e > beta) = Delta: 1e6 draws expect 1000 exceedances, sd 31.6, tolerance 5 sd."""
    rng = np.random.default_rng(11)
    L = rng.normal(size=(6, 6))
    X, a = L @ L.T, rng.normal(size=6)
    e = rng.standard_normal((1_000_000, 6)) @ np.linalg.cholesky(X).T
    count = int(np.sum(e @ a > chance_margin(X, a, 1e-3)))
    assert abs(count - 1000) < 5.0 * np.sqrt(1000)


def test_defaults_are_table_2():
    m = UncertaintyModel()
    assert m.navigation.s1 == (4e-5, 4e-3, 4e-5, 2e-5, 2e-5, 4e-5)
    assert m.navigation.s2 == (1e-4, 4e-3, 4e-5, 2e-3, 2e-3, 2e-3)
    assert (m.navigation.rho1, m.navigation.rho2) == (10_000.0, 1_000.0)
    g = m.actuation
    assert (g.sigma_s, g.sigma_p, g.sigma_r, g.sigma_a) == (2e-3, 3e-4, 3e-4, 3e-4)
    np.testing.assert_array_equal(m.process_noise.matrix, 1e-6 * np.eye(6))
    assert m.delta == 1e-3


NOT_SYMMETRIC = np.eye(6) + np.triu(np.ones((6, 6)), 1)


@pytest.mark.parametrize(
    "build, field",
    [
        (lambda: NavigationModel(s1=(-1e-5, 0, 0, 0, 0, 0)), "s1"),
        (lambda: NavigationModel(s2=(1e-3, 1e-3, 1e-3)), "s2"),
        (lambda: NavigationModel(rho1=500.0), "rho1"),
        (lambda: NavigationModel(rho2=-1.0), "rho2"),
        (lambda: GatesModel(sigma_s=-2e-3), "sigma_s"),
        (lambda: GatesModel(sigma_a=float("nan")), "sigma_a"),
        (lambda: ProcessNoise(Q_roe=np.zeros((6, 6))), "Q_roe"),
        (lambda: ProcessNoise(Q_roe=-np.eye(6)), "Q_roe"),
        (lambda: ProcessNoise(Q_roe=NOT_SYMMETRIC), "Q_roe"),
        (lambda: ProcessNoise(Q_roe=np.eye(5)), "Q_roe"),
        (lambda: UncertaintyModel(delta=0.0), "delta"),
        (lambda: UncertaintyModel(delta=1.0), "delta"),
        (lambda: UncertaintyModel(delta=-0.1), "delta"),
        (lambda: UncertaintyModel(delta=float("nan")), "delta"),
        (lambda: UncertaintyModel(fix_every=0), "fix_every"),
        (lambda: UncertaintyModel(fix_every=2.0), "fix_every"),
        (lambda: confidence_quantile(1.5), "delta"),
        (lambda: chance_margin(np.diag([1.0, -1.0, 1, 1, 1, 1]), np.ones(6)), "X"),
        (lambda: chance_margin(np.eye(6), np.ones(6), delta=2.0), "delta"),
        (lambda: chance_margin(np.eye(6), np.ones(3)), "a"),
    ],
)
def test_bad_input_raises_naming_the_field(build, field):
    with pytest.raises(ValueError, match=field):
        build()


@pytest.mark.parametrize(
    "change, field",
    [
        (lambda h: {**h, "u": h["u"][:-1]}, "u"),
        (lambda h: {**h, "stm": h["stm"][:3]}, "stm"),
        (lambda h: {**h, "B": h["B"][..., :2]}, "B"),
        (lambda h: {**h, "x": np.where(h["x"] == 0.0, np.nan, h["x"])}, "x"),
    ],
)
def test_covariance_history_rejects_inconsistent_inputs(horizon, change, field):
    h = change(horizon)
    with pytest.raises(ValueError, match=field):
        covariance_history(h["x"], h["u"], h["stm"], h["B"], h["psi"])
