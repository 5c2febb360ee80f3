"""Conic solver time of the reduced 6-DoF subproblem against the number of rows kept.

On ``--n`` nominal instances (``PDGSampleRanges.nominal()``, ``--seed``) solved cold, the
subproblem is linearized about the converged trajectory (trust radius 1, the soft region)
and solved with several row sets, each with and without the safeguard box of the soft trust
region, and without the box and the virtual control ``nu`` (what T-SCvx solves unless its
last solve needed ``nu``, ``TscvxParameters.drop_virtual``): every row, the rows tight at the
optimum plus those within the default margin (what T-SCvx keeps near the end), the tight rows
alone, and none. Each set is solved ``--repeats``
times per instance; the table gives the conic problem's size, Clarabel's interior-point
iterations and its median time (setup + solve) over all instances and repeats, beside
cvxpy's own full solve (in-place updated solver object).

Usage: PYTHONPATH=src python benchmarks/tscvx_reduced.py --n 5 --repeats 5
"""

from __future__ import annotations

import argparse

import numpy as np

from scpformer.pdg6dof import PDGSolverConfig, solve
from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.problem import SOFT_BOX_FACTOR, PDGProblem
from scpformer.problems.pdg6dof.reduced import ReducedSubproblem
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.problems.pdg6dof.tscvx import TscvxParameters, near_active_rows, row_scales
from scpformer.scp.conic import solve_timed


def row_sets(problem: PDGProblem, z, n_nodes: int) -> dict[str, tuple[np.ndarray, bool, bool]]:
    """Name -> (flag mask, keep the safeguard box, keep the virtual control)."""
    values = con.constraint_values(problem.instance, z.x, z.u)
    tight = con.tight_flags(values, problem.config.tight_tol)
    margin = TscvxParameters().margin
    near = near_active_rows(problem.instance, z, margin, row_scales(problem.instance, n_nodes))
    every = np.ones(7 * n_nodes, dtype=bool)
    masks = {"all rows": every, "tight + margin": tight | near, "tight": tight,
             "none": np.zeros_like(every)}  # fmt: skip
    variants = ((" + box", True, True), ("", False, True), (", no nu", False, False))
    return {
        f"{name}{suffix}": (mask, box, virtual)
        for name, mask in masks.items()
        for suffix, box, virtual in variants
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=5, help="nominal instances (5)")
    parser.add_argument("--repeats", type=int, default=5, help="solves per row set (5)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (0)")
    args = parser.parse_args()
    config = PDGSolverConfig()
    instances = sample_instances(
        np.random.default_rng(args.seed), args.n, PDGSampleRanges.nominal()
    )
    times: dict[str, list[float]] = {}
    sizes: dict[str, list[tuple[int, int, int, int, int]]] = {}
    for instance in instances:
        cold = solve(instance, config)
        problem = PDGProblem(instance, config)
        z = cold.trajectory
        ev = problem.evaluate(z)
        sub = problem.subproblem
        sub.set_instance(instance)
        sub.set_linearization(ev.linearization, z.x, z.u, float(z.p[0]))
        sub.set_trust_region(1.0, config.scvx.lambda_, SOFT_BOX_FACTOR, config.prox_weight)
        reduced = ReducedSubproblem(sub)
        for _ in range(args.repeats):
            call = solve_timed(sub.problem, "clarabel", reuse=True)
            assert call.solved, call.status
            times.setdefault("cvxpy full (reuse)", []).append(call.solver_time)
            for name, (keep, box, virtual) in row_sets(problem, z, config.n_nodes).items():
                sol = reduced.solve(keep, config.scvx.lambda_, box, virtual)
                assert sol.status == "optimal", (name, sol.status)
                times.setdefault(name, []).append(sol.solver_time)
                s = reduced.last_size
                sizes.setdefault(name, []).append(
                    (s.flags_kept, s.rows, s.cones, s.columns, s.iterations)
                )
    print(f"{args.n} nominal instances (seed {args.seed}), {args.repeats} repeats each")
    print(
        f"{'row set':<22} {'flags':>6} {'rows':>6} {'cones':>6} {'cols':>6} {'IPM its':>8} "
        f"{'median ms':>10}"
    )
    for name, values in times.items():
        if name in sizes:
            flags, rows, cones, cols, its = (f"{v:.0f}" for v in np.median(sizes[name], axis=0))
        else:  # cvxpy's own solve: every row and the box
            flags, rows, cones, cols, its = "350", "", "", "", ""
        print(
            f"{name:<22} {flags:>6} {rows:>6} {cones:>6} {cols:>6} {its:>8} "
            f"{1e3 * np.median(values):>10.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
