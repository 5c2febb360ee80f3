"""J_CVX of the chance-constrained rendezvous as a bound: the TPBVP solved to tight tolerances.

Its cost must not lie above the default solve of the same TPBVP (beyond that solve's own
relative gap, 1e-8) nor above the passively safe SCvx* plan it bounds, and must agree with
the default solve to the excess measured (2.5e-4 relative).
"""

from __future__ import annotations

import numpy as np
import pytest

import scpformer.robust_rendezvous as robust
from scpformer.problems.robust_rendezvous.instance import sample_instances
from scpformer.problems.robust_rendezvous.tpbvp import solve_tpbvp, tpbvp_lower_bound
from scpformer.problems.robust_rendezvous.warmstart import initial_budget
from scpformer.scp.solution import Status

DRAWS = sample_instances(np.random.default_rng(9090), 3)
DEFAULT_TOLERANCE = 1e-8


@pytest.mark.parametrize("instance", DRAWS, ids=[f"draw{i}" for i in range(len(DRAWS))])
def test_the_tpbvp_bound_lies_below_the_costs_it_bounds(instance):
    bound = tpbvp_lower_bound(instance)
    default = solve_tpbvp(instance)
    assert bound.status is Status.CONVERGED
    assert bound.cost <= default.cost * (1 + DEFAULT_TOLERANCE)
    assert bound.cost >= default.cost * (1 - 3e-4)
    plan = robust.solve(instance, verify=False)
    if plan.converged:
        assert bound.cost <= plan.cost * (1 + DEFAULT_TOLERANCE)


def test_the_budget_of_the_bound_is_a_nonnegative_number_in_both_modes():
    bound = tpbvp_lower_bound(DRAWS[0])
    for mode in ("chance", "deterministic"):
        assert initial_budget(DRAWS[0], bound, mode) >= 0.0
    with pytest.raises(ValueError, match="mode"):
        initial_budget(DRAWS[0], bound, "nope")
