"""A failed robust run reports the SCvx* solves of its status, not its fallback's."""

import dataclasses

from scpformer.data.executors import instance_rng
from scpformer.data.robust_rendezvous_family import build
from scpformer.experiments.robust_studies import scvx_star_iterations
from scpformer.problems.robust_rendezvous.scenario import RobustSolverConfig
from scpformer.robust_rendezvous import solve


def test_a_run_stopped_at_the_cap_reports_the_scvx_star_solves_not_the_tpbvp_ones():
    config = RobustSolverConfig(safety_mode="deterministic")
    capped = dataclasses.replace(config, scvx=dataclasses.replace(config.scvx, iter_max=2))
    instance = build().sample(instance_rng(0, 639))  # needs more than 2 solves from the TPBVP
    solution = solve(instance, capped, method="passive_safety", warmstart="tpbvp", verify=False)
    assert not solution.converged and solution.extras["stage"] == "tpbvp"
    assert solution.extras["stage_iterations"]["tpbvp"] != 2
    assert solution.iterations == 2  # the status's run, not the fallback's
    assert scvx_star_iterations(solution) == 2


def test_shrinking_from_the_rejected_step_converges_where_oguris_rule_repeats_it():
    """Instance 639: from the TPBVP, Oguri's halving re-solves one rejected step five times
    (radius 5000 -> 312 m, the step inside) and ends at the cap; from the step's length the
    same run converges within Table 1's 20 solves."""
    instance = build().sample(instance_rng(0, 639))
    config = RobustSolverConfig(safety_mode="deterministic")
    oguri = dataclasses.replace(
        config, scvx=dataclasses.replace(config.scvx, shrink_from_step=False)
    )
    stalled = solve(instance, oguri, method="passive_safety", warmstart="tpbvp", verify=False)
    solved = solve(instance, config, method="passive_safety", warmstart="tpbvp")
    assert not stalled.converged and scvx_star_iterations(stalled) == 20
    assert solved.converged and scvx_star_iterations(solved) < 20
    assert solved.verification is not None and solved.verification.passed
