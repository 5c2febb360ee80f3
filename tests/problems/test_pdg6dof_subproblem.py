"""The convex mass row of the 6-DoF subproblem against the discretization it replaces."""

import numpy as np
import pytest

from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import PDGProblem, PDGSolverConfig
from scpformer.problems.pdg6dof.subproblem import STATE_GROUPS
from scpformer.scp.discretization import foh_discretize

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def linearized():
    problem = PDGProblem(PDGInstance(), PDGSolverConfig())
    z = problem.initial_guess()
    disc = problem.evaluate(z).linearization
    sub = problem.subproblem
    sub.set_instance(problem.instance)
    sub.set_linearization(disc, z.x, z.u, float(z.p[0]))
    return problem, z, sub


def mass_row_bound(sub, x, u, sigma):
    """The right-hand side of the mass row for the given variable values (nu = 0)."""
    for var, (_, start, stop) in zip(sub.state_groups, STATE_GROUPS, strict=True):
        var.value = x[:, start:stop]
    sub.U.value = u
    sub.sigma.value = sigma
    sub.nu.value = np.zeros(sub.nu.shape)
    return sub.mass_row.args[1].value


def test_mass_row_is_the_discretized_mass_for_any_thrust_at_the_reference_final_time(
    linearized,
):
    problem, z, sub = linearized
    rng = np.random.default_rng(3)
    u = z.u + 0.3 * np.abs(z.u).max() * rng.standard_normal(z.u.shape)  # turns and scales
    sigma = float(z.p[0])
    flow = foh_discretize(problem.linearize, z.x, u, sigma, 2).x_next
    np.testing.assert_allclose(mass_row_bound(sub, z.x, u, sigma), flow[:, 13], rtol=0, atol=1e-12)


def test_mass_row_agrees_with_the_linearization_to_first_order_in_the_final_time(linearized):
    problem, z, sub = linearized
    sigma = float(z.p[0])
    for d_sigma in (1e-2, 1e-3):
        flow = foh_discretize(problem.linearize, z.x, z.u, sigma + d_sigma, 2)
        error = np.abs(mass_row_bound(sub, z.x, z.u, sigma + d_sigma) - flow.x_next[:, 13]).max()
        assert error < 1e-9 * (d_sigma / 1e-3) ** 2 + 1e-12  # the row is linear in sigma
