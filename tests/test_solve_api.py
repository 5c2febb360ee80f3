"""The one solve API, run as one contract on every problem family.

Each family module (``scpformer.pdg6dof``, ``scpformer.rendezvous``,
``scpformer.robust_rendezvous``) exposes ``METHODS`` and
``solve(instance, config=None, *, method=..., warmstart=None, verify=True) -> Solution``.
The cases use cheap instances and configurations (a few tenths of a second per solve once
the subproblems are compiled).
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib
import inspect
import io
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from scpformer.scp.solution import Solution


@dataclass(frozen=True)
class Case:
    """One family under the contract."""

    module: str  # the public module
    api: str  # the family's implementation of solve
    instance: Callable[[], Any]  # a cheap instance
    config: Callable[[], Any]  # a cheap configuration
    warm_method: str  # a method that takes a warm start
    warm_name: str  # a warm start of that method, by name ...
    warm_object: Callable[[Any], Any]  # ... and the same one as a provider (of the config)
    refusing: tuple[str, ...]  # methods that cannot use the warm start ``warm_name``
    own_start: dict[str, str]  # methods that take no warm start -> the record's source
    summary: Callable[[Solution, Any], str]  # the command line's summary of a solution


def _pdg6dof_instance() -> Any:
    from scpformer.pdg6dof import PDGInstance

    return PDGInstance()


def _pdg6dof_config() -> Any:
    from scpformer.pdg6dof import PDGSolverConfig

    return PDGSolverConfig()


def _pdg6dof_provider(config: Any) -> Any:
    from scpformer.problems.pdg6dof.warmstart import AnalyticWarmStart

    return AnalyticWarmStart(config.n_nodes, "straight_line")


def _pdg6dof_summary(solution: Solution, instance: Any) -> str:
    from scpformer.cli.pdg6dof import print_summary

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        print_summary(solution, instance)
    return out.getvalue()


def _rendezvous_instance() -> Any:
    from scpformer.rendezvous import RendezvousInstance

    return RendezvousInstance()


def _rendezvous_config() -> Any:
    from scpformer.rendezvous import RendezvousSolverConfig

    return RendezvousSolverConfig()


def _rendezvous_provider(config: Any) -> Any:
    from scpformer.problems.rendezvous.warmstart import RendezvousConvexWarmStart

    return RendezvousConvexWarmStart("convex", config)


def _rendezvous_summary(solution: Solution, instance: Any) -> str:
    from scpformer.cli.rendezvous import summary_rows

    return "\n".join(f"{k}  {v}" for k, v in summary_rows(solution, instance))


def _robust_instance() -> Any:
    from scpformer.robust_rendezvous import RobustInstance, RobustScenario

    # 20 impulses instead of 100: SCvx* converges in a few solves of a fraction of a second
    return RobustInstance(scenario=RobustScenario(n_nodes=20, n_ae_to_koz=10, n_safety=8))


def _robust_config() -> Any:
    from scpformer.robust_rendezvous import RobustSolverConfig

    return RobustSolverConfig(three_stage_iter_max=20)


def _robust_provider(config: Any) -> Any:
    from scpformer.problems.robust_rendezvous.warmstart import RobustTpbvpWarmStart

    return RobustTpbvpWarmStart(config)


def _robust_summary(solution: Solution, instance: Any) -> str:
    from scpformer.cli.robust_rendezvous import summary_rows

    return "\n".join(f"{k}  {v}" for k, v in summary_rows(solution))


CASES = {
    "pdg6dof": Case(
        module="scpformer.pdg6dof",
        api="scpformer.problems.pdg6dof.api",
        instance=_pdg6dof_instance,
        config=_pdg6dof_config,
        warm_method="scvx",
        warm_name="straight_line",
        warm_object=_pdg6dof_provider,
        refusing=("tscvx",),  # Algorithm 2 needs a predictor of the tight rows
        own_start={},
        summary=_pdg6dof_summary,
    ),
    "rendezvous": Case(
        module="scpformer.rendezvous",
        api="scpformer.problems.rendezvous.api",
        instance=_rendezvous_instance,
        config=_rendezvous_config,
        warm_method="scp",
        warm_name="convex",
        warm_object=_rendezvous_provider,
        refusing=("tpbvp", "convex"),  # convex problems solved from no guess
        own_start={"tpbvp": "none", "convex": "none"},
        summary=_rendezvous_summary,
    ),
    "robust_rendezvous": Case(
        module="scpformer.robust_rendezvous",
        api="scpformer.problems.robust_rendezvous.api",
        instance=_robust_instance,
        config=_robust_config,
        warm_method="passive_safety",
        warm_name="tpbvp",
        warm_object=_robust_provider,
        refusing=("three_stage",),  # the procedure makes its own warm starts
        own_start={"three_stage": "tpbvp"},  # its first stage
        summary=_robust_summary,
    ),
}
FAMILIES = pytest.mark.parametrize("family", list(CASES))


def _case(family: str) -> tuple[Case, Any]:
    case = CASES[family]
    return case, importlib.import_module(case.module)


# ======================================================================================
# the signature
# ======================================================================================
@FAMILIES
@pytest.mark.parametrize("where", ["module", "api"])
def test_solve_has_the_one_signature(family, where):
    case, module = _case(family)
    solve = module.solve if where == "module" else importlib.import_module(case.api).solve
    params = inspect.signature(solve).parameters
    assert list(params) == ["instance", "config", "method", "warmstart", "verify"]
    kinds = {name: p.kind for name, p in params.items()}
    assert kinds["instance"] is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert kinds["config"] is inspect.Parameter.POSITIONAL_OR_KEYWORD
    assert params["config"].default is None
    for name in ("method", "warmstart", "verify"):
        assert kinds[name] is inspect.Parameter.KEYWORD_ONLY, name
    assert params["warmstart"].default is None
    assert params["verify"].default is True
    assert params["method"].default in module.METHODS
    assert isinstance(module.METHODS, tuple) and len(module.METHODS) >= 2


@FAMILIES
def test_the_module_and_the_api_agree_on_methods(family):
    case, module = _case(family)
    api = importlib.import_module(case.api)
    assert module.METHODS == api.METHODS
    assert inspect.signature(module.solve).parameters["method"].default == (
        inspect.signature(api.solve).parameters["method"].default
    )


# ======================================================================================
# refused arguments: before any solve
# ======================================================================================
@FAMILIES
def test_an_unknown_method_is_a_value_error_naming_it(family):
    case, module = _case(family)
    with pytest.raises(ValueError, match="'no_such_method'") as err:
        module.solve(case.instance(), case.config(), method="no_such_method")
    assert all(method in str(err.value) for method in module.METHODS)  # says what is known


@FAMILIES
def test_an_unknown_warmstart_name_is_a_value_error_naming_it(family):
    case, module = _case(family)
    with pytest.raises(ValueError, match="no_such_warmstart"):
        module.solve(case.instance(), case.config(), method=case.warm_method,
                     warmstart="no_such_warmstart")  # fmt: skip


@FAMILIES
@pytest.mark.parametrize("given", ["name", "object"])
def test_a_method_that_takes_no_such_warm_start_refuses_it(family, given):
    case, module = _case(family)
    config = case.config()
    warmstart = case.warm_name if given == "name" else case.warm_object(config)
    assert case.refusing, "every family has a method that refuses a warm start"
    for method in case.refusing:
        with pytest.raises(ValueError, match=f"method '{method}' cannot use warmstart"):
            module.solve(case.instance(), config, method=method, warmstart=warmstart)


def test_pdg6dof_tscvx_refuses_every_analytic_warm_start():
    from scpformer.pdg6dof import PDGInstance, solve
    from scpformer.problems.pdg6dof.guess import ANALYTIC_GUESSES

    for name in ANALYTIC_GUESSES:
        with pytest.raises(ValueError, match=f"cannot use warmstart '{name}'"):
            solve(PDGInstance(), method="tscvx", warmstart=name)


# ======================================================================================
# solves
# ======================================================================================
def _same_trajectory(a: Solution, b: Solution) -> None:
    assert a.trajectory is not None and b.trajectory is not None
    for field in ("x", "u", "p"):
        np.testing.assert_array_equal(getattr(a.trajectory, field), getattr(b.trajectory, field))
    assert a.status is b.status
    assert a.iterations == b.iterations
    assert a.cost == b.cost


@FAMILIES
def test_a_warm_start_by_name_and_by_object_give_the_same_trajectory(family):
    case, module = _case(family)
    instance, config = case.instance(), case.config()
    by_name = module.solve(instance, config, method=case.warm_method, warmstart=case.warm_name,
                           verify=False)  # fmt: skip
    by_object = module.solve(instance, config, method=case.warm_method,
                             warmstart=case.warm_object(config), verify=False)  # fmt: skip
    _same_trajectory(by_name, by_object)
    assert by_name.extras["warmstart"]["used"] == by_object.extras["warmstart"]["used"]


@FAMILIES
def test_verify_false_leaves_no_verification_and_the_summary_says_so(family):
    case, module = _case(family)
    instance, config = case.instance(), case.config()
    checked = module.solve(instance, config, method=case.warm_method)
    unchecked = module.solve(instance, config, method=case.warm_method, verify=False)
    # the same solve: verification happens at convergence, so both must converge
    assert checked.converged, checked.message
    assert checked.verification is not None and checked.verification.passed
    assert "not verified" not in case.summary(checked, instance)
    assert unchecked.verification is None
    assert unchecked.trajectory is not None
    np.testing.assert_array_equal(unchecked.trajectory.x, checked.trajectory.x)
    assert "not verified" in case.summary(unchecked, instance)


def _cheap_method_config(family: str, method: str, config: Any) -> Any:
    """``config`` with the iteration caps of ``method`` low: the record is made either way."""
    if family == "robust_rendezvous" and method == "three_stage":
        scvx = dataclasses.replace(config.scvx, iter_max=2)
        return dataclasses.replace(config, scvx=scvx, three_stage_iter_max=2)
    return config


def _methods() -> list[Any]:
    out = []
    for family in CASES:
        for method in importlib.import_module(CASES[family].module).METHODS:
            slow = family == "pdg6dof" and method == "tscvx"  # loads torch and the networks
            marks = [pytest.mark.slow] if slow else []
            out.append(pytest.param(family, method, marks=marks, id=f"{family}-{method}"))
    return out


@pytest.mark.parametrize(("family", "method"), _methods())
def test_every_method_records_its_warm_start(family, method):
    case, module = _case(family)
    config = _cheap_method_config(family, method, case.config())
    solution = module.solve(case.instance(), config, method=method, verify=False)
    record = solution.extras["warmstart"]
    assert {"source", "used", "accepted", "time_s", "reason"} <= set(record)
    if method in case.own_start:
        assert record["source"] == case.own_start[method]
    else:  # the method's default warm start
        default = inspect.signature(module.solve).parameters["warmstart"].default
        assert default is None and record["source"] not in ("", "none")


def test_an_instance_not_solved_still_records_its_warm_start():
    from scpformer.pdg6dof import PDGInstance, solve

    spinning = dataclasses.replace(PDGInstance(), omega0_deg=(0.0, 0.0, 120.0))  # > omega_max
    solution = solve(spinning)
    assert solution.status.value == "infeasible_instance"
    assert solution.trajectory is None
    assert solution.extras["warmstart"]["source"] == "cubic_profile"


# ======================================================================================
# the top-level package
# ======================================================================================
def test_the_families_are_attributes_of_the_top_level_package():
    import scpformer

    for family in CASES:
        module = getattr(scpformer, family)
        assert module is importlib.import_module(f"scpformer.{family}")
        assert callable(module.solve) and module.METHODS
    with pytest.raises(AttributeError, match="no_such_family"):
        scpformer.no_such_family  # noqa: B018


def test_importing_the_package_imports_no_family():
    code = (
        "import sys, scpformer\n"
        "heavy = [m for m in ('numpy', 'scpformer.pdg6dof', 'scpformer.rendezvous', "
        "'scpformer.robust_rendezvous', 'cvxpy', 'torch') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)  # fmt: skip
    assert done.stdout.strip() == ""
