"""Which conic solver back end could make the 6-DoF SCvx subproblem faster: Clarabel (the
default), QOCO and ECOS through cvxpy, and CVXPYgen's generated solvers.

The subproblems are the real ones: every conic subproblem of cold SCvx runs on ``--n``
instances of the nominal sampler (``--seed``), recorded as their parameter values, then
solved again by each back end in turn (interleaved, one thread, a fresh solver object each
time as at the start of a run). Printed per back end: the median time inside the solver,
the median number of interior-point iterations where cvxpy reports it, and the largest
relative difference of the objective to Clarabel's.

Also printed: the size of the conic problem and of its KKT system ``n + m + p``. QOCOGEN
(the custom-solver generator of QOCO, Chari & Acikmese 2025) writes the LDL factorization of
that system out as straight-line C after scanning its ``(n + m + p)^2`` entries one by one in
Python; the count says what that costs at this size.

With ``--cvxpygen DIR`` (needs ``pip install cvxpygen`` and a C compiler; about three
minutes) the subproblem is also generated with CVXPYgen for QOCO into ``DIR``, compiled, and
every recorded subproblem is solved in turn by the generated solver, which sets QOCO up on
its first call and updates it in place after that (as an SCP loop uses it); the objectives
are compared with Clarabel's.

Usage: python benchmarks/conic_backends.py [--n 3] [--seed 11] [--cvxpygen DIR]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import statistics
import time
from pathlib import Path
from typing import Any

import cvxpy as cp
import numpy as np

import scpformer.pdg6dof as pdg
from scpformer.problems.pdg6dof import reduced
from scpformer.problems.pdg6dof.sampling import sample_instances
from scpformer.problems.pdg6dof.subproblem import CONIC_SETTINGS, compiled_subproblem
from scpformer.scp.conic import solve_timed, start_cold

BACKENDS = ("clarabel", "qoco", "ecos")


def recorded_subproblems(n: int, seed: int) -> tuple[Any, list[dict[str, np.ndarray]]]:
    """Cold SCvx on ``n`` sampled instances; the parameter values of every conic solve."""
    records: list[dict[str, np.ndarray]] = []
    original = reduced.ReducedSubproblem.solve
    subproblem = None

    def recording(self: Any, rows: np.ndarray, lambda_: float) -> Any:
        nonlocal subproblem
        subproblem = self.sub
        records.append({p.name(): np.array(p.value) for p in self.sub.problem.parameters()})
        return original(self, rows, lambda_)

    reduced.ReducedSubproblem.solve = recording  # type: ignore[method-assign]
    try:
        for instance in sample_instances(np.random.default_rng(seed), n):
            pdg.solve(instance, verify=False)
    finally:
        reduced.ReducedSubproblem.solve = original  # type: ignore[method-assign]
    return subproblem, records


def set_parameters(problem: cp.Problem, values: dict[str, np.ndarray]) -> None:
    for parameter in problem.parameters():
        parameter.value = values[parameter.name()]


def time_backends(structure: Any, records: list[dict[str, np.ndarray]]) -> None:
    problems = {
        name: compiled_subproblem(
            structure.n_nodes, structure.fix_roll, float(structure.soft), solver=name
        ).problem
        for name in BACKENDS
    }
    times: dict[str, list[float]] = {name: [] for name in BACKENDS}
    objectives: dict[str, list[float]] = {name: [] for name in BACKENDS}
    iterations: dict[str, list[int]] = {name: [] for name in BACKENDS}
    for values in records:
        for name in BACKENDS:  # interleaved: every back end sees the same load
            problem = problems[name]
            set_parameters(problem, values)
            start_cold(problem)
            call = solve_timed(problem, name, settings=CONIC_SETTINGS)
            times[name].append(call.solver_time)
            objectives[name].append(problem.value if call.solved else float("nan"))
            with contextlib.suppress(AttributeError, TypeError):
                iterations[name].append(int(problem.solver_stats.num_iters))
    reference = np.array(objectives["clarabel"])
    print(f"{len(records)} subproblems; solver time per subproblem (median), one thread")
    for name in BACKENDS:
        gap = np.nanmax(np.abs(np.array(objectives[name]) - reference) / np.abs(reference))
        its = statistics.median(iterations[name]) if iterations[name] else float("nan")
        print(
            f"  {name:9s} {1e3 * statistics.median(times[name]):7.1f} ms   "
            f"iterations {its:5.1f}   largest objective difference to clarabel {gap:.1e}"
        )


def print_sizes(problem: cp.Problem) -> None:
    data, _, _ = problem.get_problem_data(cp.CLARABEL)
    dims = data["dims"]
    n, rows = data["A"].shape[1], data["A"].shape[0]
    p = dims.zero
    m = rows - p
    size = n + m + p
    print(
        f"conic problem: {n} variables, {p} equality rows, {m} cone rows "
        f"({dims.nonneg} nonnegative, {len(dims.soc)} second-order cones), "
        f"{data['A'].nnz} nonzeros in A"
    )
    print(
        f"KKT system n + m + p = {size}; QOCOGEN scans its {size**2:,} entries one by one "
        "in Python before it writes the factorization as straight-line C"
    )


def compiled_extension(package: Path) -> Any:
    """The compiled ``cpg_module`` extension of a CVXPYgen package, loaded from its file."""
    (library,) = package.glob("cpg_module*.so")
    spec = importlib.util.spec_from_file_location("cpg_module", library)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def generated_qoco(structure: Any, records: list[dict[str, np.ndarray]], folder: Path) -> None:
    """Build the subproblem with CVXPYgen for QOCO and compare first and repeated solves."""
    from cvxpygen import cpg  # optional: pip install cvxpygen

    name = "pdg_qoco"
    problem = compiled_subproblem(structure.n_nodes, structure.fix_roll, float(structure.soft))
    problem = problem.problem
    set_parameters(problem, records[0])
    folder.mkdir(parents=True, exist_ok=True)
    previous = Path.cwd()
    os.chdir(folder)  # CVXPYgen imports the generated package by its relative name
    try:
        if not (folder / name / "cpg_solver.py").exists():
            start = time.perf_counter()
            with contextlib.suppress(ModuleNotFoundError, SyntaxError):
                cpg.generate_code(problem, code_dir=name, solver="QOCO", prefix=name)
            print(f"CVXPYgen + QOCO: generated and compiled in {time.perf_counter() - start:.0f} s")
        module = compiled_extension(folder / name)
    finally:
        os.chdir(previous)
    reference = []
    for values in records:
        set_parameters(problem, values)
        problem.solve(solver=cp.CLARABEL)
        reference.append(problem.value)
    gaps, times = [], []
    for values, ref in zip(records, reference, strict=True):
        updated = getattr(module, f"{name}_cpg_updated")()
        params = getattr(module, f"{name}_cpg_params")()
        for key, value in values.items():
            setattr(updated, key, True)
            array = np.asarray(value, dtype=float)
            setattr(params, key, float(array) if array.size == 1 else
                    array.flatten(order="F").tolist())  # fmt: skip
        start = time.perf_counter()
        result = module.solve(updated, params)
        times.append(time.perf_counter() - start)
        gaps.append(abs(result.cpg_info.obj_val - ref) / abs(ref))
    print(
        f"  generated QOCO: first call (sets the solver up) {1e3 * times[0]:.1f} ms, "
        f"objective difference to clarabel {gaps[0]:.1e}; later calls (the solver updated in "
        f"place, as an SCP loop uses it) {1e3 * statistics.median(times[1:]):.1f} ms median, "
        f"largest objective difference {max(gaps[1:]):.1e}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=3, help="instances (default: 3)")
    parser.add_argument("--seed", type=int, default=11, help="sampler seed (default: 11)")
    parser.add_argument("--cvxpygen", type=Path, help="build CVXPYgen + QOCO into this folder")
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    structure, records = recorded_subproblems(args.n, args.seed)
    print_sizes(structure.problem)
    time_backends(structure, records)
    if args.cvxpygen is not None:
        generated_qoco(structure, records, args.cvxpygen.resolve())
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
