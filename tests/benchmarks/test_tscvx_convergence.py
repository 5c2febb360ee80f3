"""benchmarks/tscvx_convergence.py: the solves it counts, and its argument checks."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from scpformer.problems.pdg6dof.problem import LEAST_CHANGE
from scpformer.scp.solution import IterationRecord, Solution, Status

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "tscvx_convergence.py"
M0 = 2.0  # initial mass: a cost of -1.9 burns 0.1
REFERENCE = -1.9  # cold SCvx's optimum: propellant 0.1


def _script():
    spec = importlib.util.spec_from_file_location("tscvx_convergence", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _record(accepted: bool, cost: float, penalty: float, status: str = "optimal"):
    return IterationRecord(
        iteration=1, accepted=accepted, cost=cost, penalty=penalty, J=cost, L=cost, rho=1.0,
        trust_radius=1.0, virtual_control_norm=0.0, step_norm=0.0,
        tight_flags=np.zeros(0, dtype=bool), time_discretization=0.0, time_solver=0.0,
        time_total=0.0, solver_status=status,
    )  # fmt: skip


def _solution(records, status=Status.CONVERGED):
    return Solution(status=status, trajectory=None, t=None, cost=REFERENCE, iterations=0,
                    history=list(records))  # fmt: skip


RUN = [
    _record(True, -1.95, 1e-1),  # 1 solve: 5% better than the optimum but infeasible
    _record(True, -1.8997, 1e-2),  # 2: 0.3% more propellant, penalty still too large
    _record(False, -1.9001, 5e-3),  # 3: rejected, the iterate is still that of solve 2
    _record(True, -1.8997, 1e-8, LEAST_CHANGE),  # its correction, no conic solve: within 0.3%
    _record(True, -1.89995, 1e-9),  # 4: within 0.05%
    _record(False, -1.90001, 1e-4),  # 5: the certificate, rejected
]


@pytest.mark.parametrize(
    "tol, solves", [(0.005, 3.0), (0.004, 3.0), (0.001, 4.0), (1e-4, math.inf)]
)
def test_solves_count_conic_solves_until_the_accepted_iterate_is_nearly_feasible_and_close(
    tol, solves
):
    instance = SimpleNamespace(m0=M0)
    counted = _script().solves_until_within(_solution(RUN), instance, REFERENCE, tol, 1e-3)
    assert counted == solves


def test_converged_solves_are_the_conic_solves_and_infinite_for_an_unconverged_run():
    script = _script()
    assert script.conic_solves_to_converge(_solution(RUN)) == 5.0
    stalled = _solution(RUN, Status.STALLED)
    assert script.conic_solves_to_converge(stalled) == math.inf


@pytest.mark.parametrize(
    "args, flag",
    [
        (["--tolerances", "0"], "--tolerances"),
        (["--tolerances", "1.5"], "--tolerances"),
        (["--penalty", "nan"], "--penalty"),
        (["--n", "0"], "--n"),
    ],
)
def test_bad_arguments_are_usage_errors_naming_the_flag(args, flag, run_benchmark, tmp_path):
    done = run_benchmark("tscvx_convergence.py", "--data", str(tmp_path), "--out", "x", *args)
    assert done.returncode == 2
    assert flag in done.stderr


def test_a_folder_without_a_manifest_is_refused_before_any_solve(run_benchmark, tmp_path):
    done = run_benchmark("tscvx_convergence.py", "--data", str(tmp_path), "--out", "x")
    assert done.returncode == 2
    assert "no manifest.json" in done.stderr


def test_a_corrupt_manifest_is_a_clear_error_not_a_traceback(run_benchmark, tmp_path):
    data = tmp_path / "pdg"
    data.mkdir()
    (data / "manifest.json").write_text("{ not json")
    done = run_benchmark("tscvx_convergence.py", "--data", str(data), "--out", str(tmp_path / "o"))
    assert done.returncode == 2
    assert "manifest" in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "o").exists()  # nothing written


def test_the_summary_names_a_tolerance_that_no_run_reached():
    rows = [
        {"method": "cold", "wall_s": 0.5, "solves_within_0.1pct": 9.0},
        {"method": "tscvx", "wall_s": 0.2, "solves_within_0.1pct": math.inf},
    ]
    text = _script().summary(rows, ["solves_within_0.1pct"])
    assert "mean  9.00" in text
    assert "reached by none of 1" in text
