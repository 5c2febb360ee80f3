"""Monte Carlo check of passive safety on a dense grid of every drift arc.

For each seed in ``--seeds`` and each waypoint, samples one Table 1 instance
(``sample_instances(seed, 1)`` with the waypoint replaced), solves it with the three-stage
procedure in each of ``--modes``, and runs :func:`monte_carlo` with ``--draws`` draws per
node through the two-body + J2 truth propagator (``--propagator``), on a grid of every
``--step`` seconds of each drift arc (the design instants included). Prints one line per plan
(max violation probability over the nodes at the design instants and on the dense grid, the
number of nodes whose violation count exceeds the one-sided 1 - 1e-4 binomial quantile at
Delta) as it goes, then the table: per waypoint, mode and solve outcome (a solve that does not
converge keeps the collision-avoidance stage, which is not passively safe), the max over plans
of both maxima and the plans that pass.

Usage: python benchmarks/robust_monte_carlo.py [--seeds 1-20] [--draws 2000] [--modes chance]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from scpformer.problems.robust_rendezvous.instance import sample_instances
from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig, monte_carlo
from scpformer.problems.robust_rendezvous.scenario import WAYPOINTS, RobustSolverConfig
from scpformer.robust_rendezvous import solve


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=_seeds, default=_seeds("1-20"), help="e.g. 1-20")
    parser.add_argument("--waypoints", nargs="+", default=list(WAYPOINTS))
    parser.add_argument("--modes", nargs="+", default=["chance"])
    parser.add_argument("--draws", type=int, default=2000)
    parser.add_argument("--step", type=float, default=5.0, help="dense grid spacing [s]")
    parser.add_argument("--propagator", default="truth")
    args = parser.parse_args()
    cfg = MonteCarloConfig(n_samples=args.draws, propagator=args.propagator,
                           dense_step_s=args.step, seed=0)  # fmt: skip
    table: dict[tuple[str, str, bool], list[tuple[float, float, bool]]] = {}
    for seed in args.seeds:
        base = sample_instances(seed, 1)[0]
        for waypoint in args.waypoints:
            instance = dataclasses.replace(base, waypoint=waypoint)
            for mode in args.modes:
                start = time.perf_counter()
                sol = solve(instance, RobustSolverConfig(safety_mode=mode), method="three_stage")
                if sol.trajectory is None:
                    print(f"seed {seed:2d} {waypoint} {mode}: no trajectory", flush=True)
                    continue
                x, u = sol.trajectory.x, sol.trajectory.u
                res = monte_carlo(instance, x, u, cfg, dynamics=sol.extras.get("dynamics"))
                bound = res.threshold()
                over = int(np.sum(res.counts(dense=True) > bound))
                row = (float(res.p_design.max()), float(res.p_dense.max()), over == 0)
                table.setdefault((waypoint, mode, sol.converged), []).append(row)
                worst = int(np.argmax(res.p_dense))
                print(f"seed {seed:2d} {waypoint} {mode:13s} {sol.status.value:15s} "
                      f"stage={sol.extras.get('stage')} max p design {row[0]:.4f} dense "
                      f"{row[1]:.4f} (node {worst}) nodes over bound {over} "
                      f"(bound {bound}/{res.n_samples}) {time.perf_counter() - start:.0f} s",
                      flush=True)  # fmt: skip
    print(f"\n{'waypoint':8s} {'mode':13s} {'solve':9s} {'plans':>5s} {'max p design':>12s} "
          f"{'max p dense':>11s} {'pass':>6s}   (Delta = {res.delta:g})")  # fmt: skip
    for (waypoint, mode, converged), rows in sorted(table.items()):
        arr = np.array([r[:2] for r in rows])
        passed = sum(r[2] for r in rows)
        label = "converged" if converged else "not conv."
        print(f"{waypoint:8s} {mode:13s} {label:9s} {len(rows):5d} {arr[:, 0].max():12.4f} "
              f"{arr[:, 1].max():11.4f} {passed:3d}/{len(rows):<3d}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
