"""J_CVX as a bound: Problem 2 solved to tight tolerances lies below every cost it bounds.

With Clarabel's default tolerances the cost of Problem 2 can exceed its optimum by 1e-4
(relative), and the SCP of Problem 3 then ends below the "lower bound". The solve of
``convex_lower_bound`` must not lie above the default solve of the same relaxation (beyond
the default solve's own tolerance, 1e-8 of the cost) nor above Problem 3's SCP cost, and it
must agree with the default solve to the excess measured (2e-4).
"""

from __future__ import annotations

import numpy as np
import pytest

import scpformer.rendezvous as rendezvous
from scpformer.problems.rendezvous.instance import sample_instances
from scpformer.problems.rendezvous.scp import convex_lower_bound
from scpformer.problems.rendezvous.warmstart import initial_constraint_to_go
from scpformer.scp.solution import Status

DRAWS = sample_instances(np.random.default_rng(4242), 6)
DEFAULT_TOLERANCE = 1e-8  # Clarabel's default relative gap


@pytest.mark.parametrize("instance", DRAWS, ids=[f"draw{i}" for i in range(len(DRAWS))])
def test_the_bound_lies_below_the_costs_it_bounds(instance):
    bound = convex_lower_bound(instance)
    default = rendezvous.solve(instance, method="convex", verify=False)
    scp = rendezvous.solve(instance, method="scp", verify=False)
    assert bound.status is Status.CONVERGED and bound.verification is None
    assert bound.cost <= default.cost * (1 + DEFAULT_TOLERANCE)
    assert bound.cost >= default.cost * (1 - 2e-4)
    assert bound.cost <= scp.cost * (1 + DEFAULT_TOLERANCE)


def test_the_constraint_to_go_of_the_bound_is_a_count():
    bound = convex_lower_bound(DRAWS[0])
    ctg = initial_constraint_to_go(DRAWS[0], bound)
    assert ctg >= 0 and float(ctg).is_integer()
