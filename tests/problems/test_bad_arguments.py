"""Public entry points name the bad argument in a TypeError or ValueError.

Each case fails before any conic solve: wrong types (a string, a dict, a list), wrong shapes,
NaN, complex numbers and JSON strings where booleans belong.
"""

from __future__ import annotations

import numpy as np
import pytest

from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import solve as solve_pdg
from scpformer.problems.rendezvous.instance import RendezvousInstance
from scpformer.problems.rendezvous.problem import solve as solve_rdv
from scpformer.problems.rendezvous.scenario import RendezvousScenario, VerificationTolerances
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.scenario import RobustScenario
from scpformer.robust_rendezvous import solve as solve_robust
from scpformer.scp.solution import Trajectory


def default_guess_shapes() -> dict[str, tuple[int, ...]]:
    from scpformer.problems.pdg6dof.guess import straight_line_guess
    from scpformer.problems.pdg6dof.problem import PDGSolverConfig

    x, u, _ = straight_line_guess(PDGInstance(), PDGSolverConfig().n_nodes)
    return {"x": x.shape, "u": u.shape}


def guess(**change) -> Trajectory:
    shapes = default_guess_shapes()
    parts = {"x": np.ones(shapes["x"]), "u": np.ones(shapes["u"]), "p": np.ones(1)}
    return Trajectory(**(parts | change))


PDG_CASES = {
    "instance-a-string": (lambda: solve_pdg("nominal"), TypeError, "instance"),
    "instance-a-dict": (lambda: solve_pdg({"r0": [4, 4, 0]}), TypeError, "instance"),
    "config-a-string": (lambda: solve_pdg(PDGInstance(), config="fast"), TypeError, "config"),
    "config-a-dict": (lambda: solve_pdg(PDGInstance(), config={}), TypeError, "config"),
    "eta-init-a-string": (lambda: solve_pdg(PDGInstance(), eta_init="big"), TypeError, "eta_init"),
    "eta-init-negative": (lambda: solve_pdg(PDGInstance(), eta_init=-1.0), ValueError, "eta_init"),
    "guess-a-list": (lambda: solve_pdg(PDGInstance(), guess=[1.0, 2.0]), TypeError, "guess"),
    "guess-wrong-shape": (
        lambda: solve_pdg(PDGInstance(), guess=guess(x=np.ones((3, 14)))),
        ValueError,
        "guess.x",
    ),
    "guess-with-nan": (
        lambda: solve_pdg(
            PDGInstance(), guess=guess(u=np.full(default_guess_shapes()["u"], np.nan))
        ),
        ValueError,
        "guess.u",
    ),
    "guess-p-wrong-length": (
        lambda: solve_pdg(PDGInstance(), guess=guess(p=np.ones(2))),
        ValueError,
        "guess.p",
    ),
    "guess-final-time-negative": (
        lambda: solve_pdg(PDGInstance(), guess=guess(p=-np.ones(1))),
        ValueError,
        r"guess.p\[0\] \(the final time t_f\) must be positive",
    ),
}


def test_a_bad_trajectory_is_summarized_not_printed():
    u = np.ones(default_guess_shapes()["u"])
    u[4, 1] = u[7, 2] = np.nan
    with pytest.raises(ValueError) as err:
        solve_pdg(PDGInstance(), guess=guess(u=u))
    message = str(err.value)
    assert message == (
        f"guess.u must be finite, but 2 of its {u.size} entries are not (the first at index (4, 1))"
    )


@pytest.mark.parametrize("call, error, name", PDG_CASES.values(), ids=PDG_CASES.keys())
def test_pdg6dof_solve_names_the_bad_argument(call, error, name):
    with pytest.raises(error, match=name):
        call()


RENDEZVOUS_CASES = {
    "rendezvous-instance-a-string": (lambda: solve_rdv("nominal"), ValueError, "instance"),
    "rendezvous-config-a-string": (
        lambda: solve_rdv(RendezvousInstance(), "convex", config="fast"),
        TypeError,
        "config",
    ),
    "rendezvous-warmstart-wrong-shape": (
        lambda: solve_rdv(RendezvousInstance(), "scp", [[1.0, 2.0]], verify=False),
        ValueError,
        "warmstart",
    ),
    "robust-instance-a-dict": (lambda: solve_robust({}), ValueError, "instance"),
    "robust-config-a-string": (lambda: solve_robust(RobustInstance(), "fast"), TypeError, "config"),
    "robust-warmstart-a-list": (
        lambda: solve_robust(
            RobustInstance(), method="passive_safety", warmstart=[1.0], verify=False
        ),
        ValueError,
        "warm start",
    ),
}


@pytest.mark.parametrize(
    "call, error, name", RENDEZVOUS_CASES.values(), ids=RENDEZVOUS_CASES.keys()
)
def test_rendezvous_solves_name_the_bad_argument(call, error, name):
    with pytest.raises(error, match=name):
        call()


VALUE_CASES = {
    "complex-r0": (lambda: PDGInstance(r0=(4.0 + 1e-3j, 4.0, 0.0)), "r0"),
    "string-r0": (lambda: PDGInstance(r0=("4", 4.0, 0.0)), "r0"),
    "bool-m0": (lambda: PDGInstance(m0=True), "m0"),
    "huge-r0": (lambda: PDGInstance(r0=(1e9, 0.0, 0.0)), "r0"),
    "complex-roe0": (
        lambda: RendezvousInstance(roe0_m=np.array([0, 50, 0, 80, 0, 140], dtype=complex) + 1j),
        "roe0_m",
    ),
    "huge-roe0": (lambda: RendezvousInstance(roe0_m=(0, 1e8, 0, 80, 0, 140)), "roe0_m"),
    "string-j2": (lambda: RendezvousScenario(j2="false"), "scenario.j2"),
    "int-j2": (lambda: RendezvousScenario(j2=0), "scenario.j2"),
    "robust-string-j2": (lambda: RobustScenario(j2="false"), "scenario.j2"),
    "string-consistent-state": (
        lambda: VerificationTolerances(consistent_initial_state="yes"),
        "consistent_initial_state",
    ),
}


@pytest.mark.parametrize("build, name", VALUE_CASES.values(), ids=VALUE_CASES.keys())
def test_instances_check_reals_and_booleans_by_type(build, name):
    with pytest.raises((TypeError, ValueError), match=name):
        build()


def test_a_type_error_is_still_caught_as_a_value_error():
    with pytest.raises(ValueError, match=r"scenario\.j2"):
        RendezvousScenario(j2="false")


def test_numpy_booleans_and_integers_are_accepted():
    assert RendezvousScenario(j2=np.bool_(False)).j2 is False
    assert PDGInstance(r0=np.array([4, 4, 0])).r0 == (4.0, 4.0, 0.0)


def test_a_failed_replay_prints_its_reason_instead_of_a_key_error():
    from scpformer.cli.rendezvous import summary_rows
    from scpformer.scp.solution import Solution, Status, Verification

    failed = Verification(False, {}, float("inf"), {}, {}, "replay failed: orbit escaped")
    solution = Solution(
        status=Status.VERIFICATION_FAILED,
        trajectory=None,
        t=None,
        cost=float("nan"),
        iterations=1,
        verification=failed,
    )
    rows = dict(summary_rows(solution, RendezvousInstance()))
    assert rows["verified (replay)"] == "no (replay failed: orbit escaped)"
