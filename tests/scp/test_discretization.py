import numpy as np
from scipy.integrate import solve_ivp

from scpformer.dynamics import powered_descent as pd
from scpformer.problems.pdg6dof.guess import straight_line_guess
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.scp.discretization import foh_discretize, foh_flow

INSTANCE = PDGInstance(omega0_deg=(0.0, 5.0, -3.0))
MODEL = INSTANCE.constants.model()
N = 50  # Table 1; with t_f = 5 an interval lasts about 0.1 U_T


def f(x, u):
    return pd.dynamics(MODEL, x, u)


def lin(x, u):
    return pd.linearize(MODEL, x, u)


def reference():
    x, u, _ = straight_line_guess(INSTANCE, N)
    u = u + np.random.default_rng(0).uniform(-0.3, 0.3, u.shape)
    return x, u, 5.0


def integrate_interval(x0, u0, u1, tf, k):
    dt = tf / (N - 1)
    sol = solve_ivp(
        lambda t, x: f(x, u0 + (t / dt) * (u1 - u0)),
        (0, dt),
        x0,
        method="DOP853",
        rtol=1e-12,
        atol=1e-12,
    )
    return sol.y[:, -1]


def test_flow_matches_adaptive_integration_of_each_interval():
    x, u, tf = reference()
    disc = foh_discretize(lin, x, u, tf, n_sub=4)
    for k in (0, 25, N - 2):
        np.testing.assert_allclose(
            disc.x_next[k], integrate_interval(x[k], u[k], u[k + 1], tf, k), atol=1e-8
        )


def test_linear_model_is_exact_at_the_reference_and_first_order_nearby():
    x, u, tf = reference()
    disc = foh_discretize(lin, x, u, tf, n_sub=4)
    rng = np.random.default_rng(1)
    dx, du, ds = rng.normal(size=14), rng.normal(size=3), 0.3
    k = 4
    for eps in (1e-2, 1e-3):
        exact = integrate_interval(x[k] + eps * dx, u[k] + eps * du, u[k + 1], tf + eps * ds, k)
        linear = (
            disc.A[k] @ (x[k] + eps * dx)
            + disc.Bm[k] @ (u[k] + eps * du)
            + disc.Bp[k] @ u[k + 1]
            + disc.S[k] * (tf + eps * ds)
            + disc.z[k]
        )
        # the remainder is second order: it shrinks 100x when eps shrinks 10x
        assert np.abs(exact - linear).max() < 0.5 * eps**2


def test_sensitivities_match_finite_differences_of_the_flow():
    x, u, tf = reference()
    disc = foh_discretize(lin, x, u, tf, n_sub=8)
    k, h = 3, 1e-6

    def flow(xk=x[k], uk=u[k], ukp=u[k + 1], s=tf):
        xs, us = x.copy(), u.copy()
        xs[k], us[k], us[k + 1] = xk, uk, ukp
        return foh_discretize(lin, xs, us, s, n_sub=8).x_next[k]

    S_fd = (flow(s=tf + h) - flow(s=tf - h)) / (2 * h)
    Bp_fd = np.stack(
        [(flow(ukp=u[k + 1] + h * e) - flow(ukp=u[k + 1] - h * e)) / (2 * h) for e in np.eye(3)],
        axis=1,
    )
    np.testing.assert_allclose(disc.S[k], S_fd, atol=1e-6)
    np.testing.assert_allclose(disc.Bp[k], Bp_fd, atol=1e-6)


def test_flow_alone_is_the_flow_of_the_full_discretization():
    x, u, tf = reference()
    for n_sub in (1, 2):
        disc = foh_discretize(lin, x, u, tf, n_sub=n_sub)
        np.testing.assert_array_equal(foh_flow(f, x, u, tf, n_sub), disc.x_next)
