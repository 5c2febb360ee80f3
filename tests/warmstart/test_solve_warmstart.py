"""The solve entry points take warm start providers, run the SCP after them and record them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from warmstart_standins import AffineNormalization, ReplayModel, replay_model

from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import PDGProblem, PDGSolverConfig
from scpformer.problems.pdg6dof.problem import solve as solve_pdg
from scpformer.problems.rendezvous import sample_instances, solve
from scpformer.problems.robust_rendezvous import RobustInstance, solve_tpbvp
from scpformer.problems.robust_rendezvous import solve as solve_robust
from scpformer.scp.solution import Status
from scpformer.warmstart import (
    AnalyticWarmStart,
    ArtWarmStart,
    GivenWarmStart,
    RendezvousConvexWarmStart,
    RobustTpbvpWarmStart,
    WarmStartRecord,
    WarmStartResult,
    as_provider,
)

N = 100


@pytest.fixture(scope="module")
def norm():
    return AffineNormalization.random(N, seed=3)


@pytest.fixture(scope="module")
def instance():
    return sample_instances(np.random.default_rng(0), 1)[0]


def test_named_warm_starts_are_providers_and_the_solution_records_them(instance):
    for name in ("tpbvp", "convex"):
        warm = solve(instance, name, verify=False)
        sol = solve(instance, "scp", name, verify=False)
        record = sol.extras["warmstart"]
        assert sol.status is Status.CONVERGED
        assert record["source"] == record["used"] == name and record["accepted"]
        assert record["cost"] == pytest.approx(warm.cost) and record["time_s"] > 0.0
        assert record["constraint_to_go"] >= 0
    fixed = solve(instance, "scp", warm.trajectory, verify=False)
    assert fixed.extras["warmstart"]["source"] == "trajectory"


def test_rendezvous_scp_runs_after_art_and_never_returns_its_guess(instance, norm):
    scp = solve(instance, "scp", verify=False)
    cvx = solve(instance, "convex", verify=False)
    provider = ArtWarmStart(replay_model(norm, cvx.trajectory.u[None]), norm)
    result = provider.guess(instance)
    sol = solve(instance, "scp", provider, verify=False)
    assert sol.status is Status.CONVERGED and sol.iterations >= 1
    assert sol.cost == pytest.approx(scp.cost, rel=1e-4)
    assert not np.allclose(sol.trajectory.x, result.trajectory.x)  # C_ART > 0: SCP moved it
    record = sol.extras["warmstart"]
    assert record["source"] == "art" and record["accepted"]
    assert record["details"]["art_mode"] == "dynamics"
    assert record["constraint_to_go"] == result.record.constraint_to_go > 0
    again = solve(instance, "scp", result, verify=False)  # a precomputed result, used as is
    assert again.extras["warmstart"] == result.record.to_dict()
    assert again.cost == pytest.approx(sol.cost, rel=1e-9)


def test_a_failed_art_warm_start_is_a_status_not_a_crash(instance, norm):
    class Failing:
        def guess(self, instance):
            record = WarmStartRecord(source="art", time_s=0.0, cost=np.nan,
                                     constraint_to_go=np.nan, accepted=False,
                                     reason="no R(t_1)")  # fmt: skip
            return WarmStartResult(None, record)

    sol = solve(instance, "scp", Failing(), verify=False)
    assert sol.status is Status.SOLVER_FAILED and "warm start failed: no R(t_1)" in sol.message
    assert sol.trajectory is None and sol.extras["warmstart"]["source"] == "art"


def test_as_provider_maps_names_results_and_trajectories_and_refuses_the_rest(instance):
    named = {"convex": lambda: RendezvousConvexWarmStart("convex")}
    assert isinstance(as_provider("convex", named), RendezvousConvexWarmStart)
    result = WarmStartResult(None, WarmStartRecord(source="x", time_s=0.0, cost=np.nan,
                                                   constraint_to_go=np.nan))  # fmt: skip
    assert as_provider(result, named).guess(instance) is result
    assert isinstance(as_provider(np.zeros((101, 6)), named), GivenWarmStart)
    with pytest.raises(ValueError, match=r"warmstart must be one of \('convex',\)"):
        as_provider("art", named)
    with pytest.raises(ValueError, match="warmstart must be a name, a WarmStart provider"):
        as_provider(3.0, named)
    with pytest.raises(ValueError, match="kind must be one of"):
        RendezvousConvexWarmStart("scp")


def test_robust_solve_from_art_records_it_and_keeps_the_tpbvp_as_fallback_stage(norm):
    instance = RobustInstance(waypoint="-T")
    tpbvp = solve_tpbvp(instance)
    provider = ArtWarmStart(replay_model(norm, tpbvp.trajectory.u[None]), norm,
                            family="robust-rendezvous", mode="deterministic",
                            acceptance=None)  # fmt: skip
    sol = solve_robust(instance, mode="deterministic", warmstart=provider)
    assert sol.converged and sol.extras["stage"] == "passive_safety"
    assert set(sol.extras["stage_status"]) == {"tpbvp", "passive_safety"}
    record = sol.extras["warmstart"]
    assert record["source"] == "art" and record["accepted"]
    assert record["constraint_to_go"] > 0 and sol.extras["violation_budget"][0] == 0
    with pytest.raises(ValueError, match="the provider's mode 'deterministic' differs"):
        solve_robust(instance, mode="chance", warmstart=provider)


def test_robust_rejected_art_falls_back_to_ps_cvx(norm):
    instance = RobustInstance(waypoint="-T")
    idle = ReplayModel(norm.encode("action", np.zeros((1, N, 3))))
    provider = ArtWarmStart(idle, norm, family="robust-rendezvous", mode="deterministic")
    from_art = solve_robust(instance, mode="deterministic", warmstart=provider)
    ps_cvx = solve_robust(instance, mode="deterministic", warmstart="tpbvp")
    record = from_art.extras["warmstart"]
    assert not record["accepted"] and record["used"] == "tpbvp"
    assert ps_cvx.extras["warmstart"]["source"] == "tpbvp"
    assert from_art.cost == pytest.approx(ps_cvx.cost, rel=1e-9)
    assert record["cost"] == pytest.approx(ps_cvx.extras["warmstart"]["cost"])


def test_robust_tpbvp_provider_records_the_eq7_budget_of_cvx():
    instance = RobustInstance(waypoint="-T")
    chance = RobustTpbvpWarmStart(mode="chance").guess(instance).record
    deterministic = RobustTpbvpWarmStart(mode="deterministic").guess(instance).record
    assert chance.source == "tpbvp" and chance.constraint_to_go >= deterministic.constraint_to_go
    with pytest.raises(ValueError, match="instance must be a RobustInstance"):
        RobustTpbvpWarmStart().guess(sample_instances(np.random.default_rng(0), 1)[0])


def test_cubic_profile_provider_is_the_6dof_default_guess():
    instance, config = PDGInstance(), PDGSolverConfig(n_nodes=10)
    result = AnalyticWarmStart(n_nodes=10, profile="cubic_profile").guess(instance)
    default = PDGProblem(instance, config).initial_guess()
    for key in ("x", "u", "p"):
        assert np.array_equal(getattr(result.trajectory, key), getattr(default, key))
    assert result.record.source == "cubic_profile" and result.record.cost < 0  # -m_N
    line = AnalyticWarmStart(n_nodes=10).guess(instance)
    assert line.record.source == "straight_line"
    assert not np.array_equal(line.trajectory.x, default.x)
    with pytest.raises(ValueError, match="profile must be one of cubic_profile, straight_line"):
        AnalyticWarmStart(profile="spline")


@pytest.mark.slow
def test_6dof_solve_takes_a_provider_and_records_it():
    instance, config = PDGInstance(), PDGSolverConfig()
    by_default = solve_pdg(instance, config)
    by_provider = solve_pdg(instance, config, AnalyticWarmStart(config.n_nodes, "cubic_profile"))
    assert by_provider.extras["warmstart"]["source"] == "cubic_profile"
    assert by_provider.status is by_default.status
    assert by_provider.cost == pytest.approx(by_default.cost, rel=1e-9)


def test_art_on_an_infeasible_instance_reports_the_convex_failure(norm):
    instance = sample_instances(np.random.default_rng(0), 1)[0]
    scenario = dataclasses.replace(instance.scenario, cone_vertex_setback_m=0.0)
    instance = dataclasses.replace(instance, scenario=scenario)
    provider = ArtWarmStart(ReplayModel(np.zeros((1, N, 3))), norm)
    result = provider.guess(instance)
    assert result.trajectory is None and not result.record.accepted
    assert "no R(t_1) = -J_CVX: the convex warm start failed" in result.record.reason
    sol = solve(instance, "scp", provider, verify=False)
    assert sol.status is Status.INFEASIBLE_INSTANCE and "warm start failed" in sol.message


def test_old_interface_module_forwards_with_a_deprecation_naming_the_new_home():
    import scpformer.scp.warmstart as interface
    from scpformer.warmstart import base

    with pytest.warns(DeprecationWarning, match="import it from scpformer.scp.warmstart"):
        assert base.WarmStartResult is interface.WarmStartResult
    with pytest.raises(AttributeError):
        base.not_an_interface_name  # noqa: B018
