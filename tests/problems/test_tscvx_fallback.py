"""A T-SCvx run that falls back to cold SCvx reports the whole path it took.

The T-SCvx loop is capped at one conic solve (it cannot converge in one), so the solve falls
back to cold SCvx from the cubic profile; the returned solution must count both runs'
solves, history and wall time, and its warm-start record must name the guess the returned
trajectory came from, not the rejected learned one.
"""

from __future__ import annotations

import dataclasses

import pytest

from scpformer import pdg6dof
from scpformer.problems.pdg6dof import tscvx as tscvx_module
from scpformer.problems.pdg6dof.instance import PDGInstance


@pytest.fixture(scope="module")
def cold():
    return pdg6dof.solve(PDGInstance(), method="scvx", verify=False)


@pytest.fixture
def fell_back(monkeypatch):
    real = tscvx_module.solve_scvx

    def one_solve(problem, guess, params, **kwargs):
        return real(problem, guess, dataclasses.replace(params, iter_max=1), **kwargs)

    monkeypatch.setattr(tscvx_module, "solve_scvx", one_solve)
    return pdg6dof.solve(PDGInstance(), method="tscvx", verify=False)


def test_the_fallback_counts_both_runs_solves_and_history(fell_back, cold):
    assert fell_back.extras["tscvx"]["fallback"] == "cold"
    assert fell_back.extras["tscvx_iterations"] == 1
    assert fell_back.converged and cold.converged
    assert fell_back.iterations == 1 + cold.iterations
    assert len(fell_back.history) == len(cold.history) + 1
    numbers = [record.iteration for record in fell_back.history]
    assert numbers == sorted(numbers) and len(set(numbers)) == len(numbers)


def test_the_fallback_times_the_whole_path(fell_back):
    """The solver and total times are those of every iteration of both runs."""
    timing = fell_back.timing
    history = fell_back.history
    assert timing is not None
    assert timing.solver == pytest.approx(sum(r.time_solver for r in history), rel=1e-6)
    assert timing.total >= sum(r.time_total for r in history) * (1 - 1e-6)


def test_the_fallback_record_names_the_guess_that_was_used(fell_back, cold):
    record = fell_back.extras["warmstart"]
    assert record["source"] == "tscvx" and not record["accepted"]
    assert record["fallback_source"] == "cubic_profile" and record["used"] == "cubic_profile"
    assert "cold" in record["reason"]
    assert fell_back.cost == pytest.approx(cold.cost, rel=1e-9)  # the cold run's trajectory
