"""T-SCvx with an oracle predictor against cold SCvx: the most the networks can give.

For each of ``--n`` nominal instances (``PDGSampleRanges.nominal()``, ``--seed``) cold SCvx is
solved first; the oracle then answers ``predict_tight(theta, k)`` with the flags of the cold
run's k-th solve (the last one beyond its length) and ``predict_solution`` with the cold
optimum. Side by side in one process, per instance:

* ``cold``: SCvx from the straight-line guess (full subproblems);
* ``guess only``: SCvx from the oracle's solution, full subproblems, eta_init 1;
* ``T-SCvx``: Algorithm 2 with the oracle (reduced subproblems, Eq. 22), eta_init 1;
* ``T-SCvx eta 0.01``: the same with Table 1's eta_reduced,init;
* ``rows only``: Algorithm 2 with the oracle's flags from the straight-line guess (the
  reduction alone, along a whole run);
* ``noisy guess only`` / ``noisy T-SCvx``: a stand-in for imperfect networks, the oracle's
  solution with Gaussian noise of ``--noise`` times the trust-region scale of each variable
  (:func:`~scpformer.problems.pdg6dof.subproblem.trust_region_scales`) and its flags with
  ``--flip`` of them flipped; full subproblems, then Algorithm 2.

Prints per-instance status, solves and wall time, then medians of wall time, solves, conic
time per solve and (name, node) rows kept, and the largest propellant gap to cold SCvx.

Usage: PYTHONPATH=src python benchmarks/tscvx_oracle.py --n 10 --seed 0
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from scpformer.pdg6dof import PDGSolverConfig, solve
from scpformer.problems.pdg6dof.guess import straight_line_guess
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.metrics import propellant_gap
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances
from scpformer.problems.pdg6dof.subproblem import trust_region_scales
from scpformer.problems.pdg6dof.tscvx import TscvxParameters
from scpformer.scp.solution import Solution, Trajectory
from scpformer.warmstart.tscvx import TscvxWarmStart


class Oracle:
    """Predictor API answering with a cold solve (its flags per solve, its optimum)."""

    def __init__(self, cold: Solution, guess: tuple | None = None, flip: float = 0.0) -> None:
        self.cold, self.guess, self.flip = cold, guess, flip
        self.n_nodes = cold.trajectory.x.shape[0]

    def predict_tight(self, theta: np.ndarray, k: np.ndarray) -> np.ndarray:
        return np.array([self._flags(int(j)) for j in np.atleast_1d(k)])

    def _flags(self, k: int) -> np.ndarray:
        history = self.cold.history
        flags = history[min(k, len(history)) - 1].tight_flags
        if self.flip:
            flipped = np.random.default_rng(k).random(flags.shape) < self.flip
            flags = flags ^ flipped
        return flags

    def predict_solution(self, theta: np.ndarray) -> tuple:
        if self.guess is not None:
            return self.guess
        z = self.cold.trajectory
        return z.x, z.u, float(z.p[0])


def noisy(instance: PDGInstance, z: Trajectory, noise: float, seed: int) -> tuple:
    """``z`` with Gaussian noise of ``noise`` trust-region scales per variable."""
    rng = np.random.default_rng(seed)
    sx, su, ss = trust_region_scales(instance)
    x = z.x + noise * sx * rng.normal(size=z.x.shape)
    u = z.u + noise * su * rng.normal(size=z.u.shape)
    return x, u, float(z.p[0] + noise * ss * rng.normal())


def variants(
    instance: PDGInstance, cold: Solution, config: PDGSolverConfig, args: argparse.Namespace
) -> dict[str, Callable[[], Solution]]:
    oracle = Oracle(cold)
    line = Oracle(cold, straight_line_guess(instance, config.n_nodes))
    paper = TscvxParameters(eta_init=0.01)
    fuzzy = Oracle(cold, noisy(instance, cold.trajectory, args.noise, args.seed), args.flip)
    fuzzy_guess = TscvxWarmStart(fuzzy).guess(instance).trajectory
    eta_one = replace(config, scvx=replace(config.scvx, eta_init=1.0))

    def tscvx(provider: TscvxWarmStart) -> Solution:
        return solve(instance, config, method="tscvx", warmstart=provider)

    return {
        "guess only": lambda: solve(instance, eta_one, warmstart=cold.trajectory),
        "T-SCvx": lambda: tscvx(TscvxWarmStart(oracle)),
        "T-SCvx eta 0.01": lambda: tscvx(TscvxWarmStart(oracle, paper)),
        "rows only": lambda: tscvx(TscvxWarmStart(line)),
        "noisy guess only": lambda: solve(instance, eta_one, warmstart=fuzzy_guess),
        "noisy T-SCvx": lambda: tscvx(TscvxWarmStart(fuzzy)),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10, help="nominal instances (10)")
    parser.add_argument("--seed", type=int, default=0, help="sampling seed (0)")
    parser.add_argument("--noise", type=float, default=0.02, help="guess noise (0.02)")
    parser.add_argument("--flip", type=float, default=0.02, help="flipped flags (0.02)")
    args = parser.parse_args()
    config = PDGSolverConfig()
    instances = sample_instances(
        np.random.default_rng(args.seed), args.n, PDGSampleRanges.nominal()
    )
    solve(PDGInstance(), config)  # compile/load the subproblem, untimed
    rows: dict[str, list[dict]] = {}
    for index, instance in enumerate(instances):
        t0 = time.perf_counter()
        cold = solve(instance, config)
        runs = {"cold": (cold, time.perf_counter() - t0)}
        for name, run in variants(instance, cold, config, args).items():
            t0 = time.perf_counter()
            solution = run()
            runs[name] = (solution, time.perf_counter() - t0)
        line = [f"{index:>2}"]
        for name, (solution, wall) in runs.items():
            log = solution.extras.get("tscvx", {})
            rows.setdefault(name, []).append({
                "status": solution.status.value,
                "solves": solution.iterations,
                "wall": wall,
                "conic": solution.timing.solver / max(solution.iterations, 1),
                "kept": float(np.median(log["rows_kept"])) if log.get("rows_kept") else 350.0,
                "fallback": log.get("fallback"),
                "gap": propellant_gap(instance, solution.cost, cold.cost),
            })  # fmt: skip
            status = solution.status.value[:4]
            line.append(f"{name}: {status} {solution.iterations:>3} {wall:6.2f}s")
        print(" | ".join(line), flush=True)
    print(f"\n{args.n} nominal instances, seed {args.seed}; medians over instances")
    header = f"{'variant':<16} {'conv':>5} {'wall s':>7} {'solves':>6} {'ms/solve':>8}"
    print(header + f" {'rows kept':>9} {'fallbacks':>9} {'max |gap|':>9}")
    for name, items in rows.items():
        conv = np.mean([r["status"] == "converged" for r in items])
        med = {k: np.median([r[k] for r in items]) for k in ("wall", "solves", "conic", "kept")}
        fallbacks = sum(r["fallback"] is not None for r in items)
        gap = max(abs(r["gap"]) for r in items)
        print(
            f"{name:<16} {conv:>5.0%} {med['wall']:>7.3f} {med['solves']:>6.0f} "
            f"{1e3 * med['conic']:>8.1f} {med['kept']:>9.0f} {fallbacks:>9} {gap:>9.2%}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
