"""ART -> SCP without the convex solve, against CVX -> SCP, end to end, on fresh draws.

The ART paper conditions the transformer on ``R(t_1) = -J_CVX``, which costs the convex
solve that CVX -> SCP starts from anyway. Its ablation allows other choices of ``R(t_1)``;
here ``R(t_1)`` is a quantile (25%, 50%, 75%) of ``J_CVX`` over ``--calibration`` draws of the
sampler with ``--calibration-seed`` (a stand-in for the training returns, drawn apart from
the test draws), so ART's path is the rollout and the SCP alone. ``-J_CVX`` (the paper's
choice) runs beside it. No acceptance check: the ART paper always warm-starts with ART.

On ``--n`` draws of ``--seed`` each path solves Problem 3 through
``scpformer.rendezvous.solve(instance, method="scp", warmstart=...)``, verification on, one
torch thread, the order of the paths reversed on every other draw. Printed per path:
converged runs, median and mean wall time of the whole call (guess, every SCP iteration,
the check), the median guess time, SCP iterations, per-draw cost against CVX -> SCP
(lower / equal / higher, by more than 1e-3 mm/s) and per-draw time against it (faster / tie /
slower, a tie within 5%).

Usage: python benchmarks/art_without_convex.py --seed 515151 --n 40 [--calibration 30]
       [--calibration-seed 777001] [--model RUN]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

import scpformer
import scpformer.rendezvous as rendezvous
from scpformer.problems.rendezvous.instance import sample_instances
from scpformer.warmstart.art import ArtWarmStart

QUANTILES = {"ART, R(t1) = -q25": 0.25, "ART, R(t1) = -q50": 0.5, "ART, R(t1) = -q75": 0.75}
TIE = 1.05
COST_TIE = 1e-6  # m/s (1e-3 mm/s)


def providers(model: Path, calibration: int, seed: int) -> dict[str, Any]:
    draws = sample_instances(np.random.default_rng(seed), calibration)
    costs = [rendezvous.solve(i, method="convex", verify=False).cost for i in draws]
    out: dict[str, Any] = {"CVX": "convex"}
    for name, q in QUANTILES.items():
        rtg = -float(np.quantile(costs, q))
        print(f"{name}: R(t1) = {rtg * 1e3:.2f} mm/s")
        out[name] = ArtWarmStart.from_checkpoint(model, rtg=rtg)
    out["ART, R(t1) = -J_CVX"] = ArtWarmStart.from_checkpoint(model)
    return out


def measure(paths: dict[str, Any], instances: list) -> dict[str, list[dict]]:
    rendezvous.solve(instances[0], method="scp", warmstart=paths["ART, R(t1) = -J_CVX"])
    rows: dict[str, list[dict]] = {name: [] for name in paths}
    for index, instance in enumerate(instances):
        order = list(paths) if index % 2 == 0 else list(paths)[::-1]
        for name in order:
            start = time.perf_counter()
            solution = rendezvous.solve(instance, method="scp", warmstart=paths[name])
            rows[name].append(
                {
                    "wall": time.perf_counter() - start,
                    "converged": solution.converged,
                    "cost": solution.cost,
                    "iterations": solution.iterations,
                    "guess": solution.extras["warmstart"].get("time_s") or 0.0,
                }
            )
    return rows


def summarize(rows: dict[str, list[dict]]) -> None:
    base_wall = np.array([r["wall"] for r in rows["CVX"]])
    base_cost = np.array([r["cost"] for r in rows["CVX"]])
    for name, runs in rows.items():
        wall = np.array([r["wall"] for r in runs])
        cost = np.array([r["cost"] for r in runs])
        iters = np.array([r["iterations"] for r in runs])
        diff = cost - base_cost
        faster = int((wall < base_wall / TIE).sum())
        slower = int((wall > base_wall * TIE).sum())
        print(
            f"{name:22s} converged {sum(r['converged'] for r in runs)}/{len(runs)}  "
            f"wall median {np.median(wall):.3f} s mean {wall.mean():.3f} s  guess median "
            f"{np.median([r['guess'] for r in runs]):.3f} s  SCP iterations median "
            f"{np.median(iters):.0f} mean {iters.mean():.2f}  cost vs CVX lower/equal/higher "
            f"{(diff < -COST_TIE).sum()}/{(np.abs(diff) <= COST_TIE).sum()}/"
            f"{(diff > COST_TIE).sum()} (no solution {np.isnan(diff).sum()})  time vs CVX "
            f"faster/tie/slower {faster}/{len(runs) - faster - slower}/{slower}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, required=True, help="seed of the test draws")
    parser.add_argument("--n", type=int, default=40, help="test draws (default: 40)")
    parser.add_argument("--calibration", type=int, default=30, help="draws for the quantiles")
    parser.add_argument("--calibration-seed", type=int, default=777001)
    default = Path(scpformer.__file__).parent / "pretrained" / "art-rendezvous" / "checkpoint.pt"
    parser.add_argument("--model", type=Path, default=default, help="ART checkpoint")
    args = parser.parse_args()
    torch.set_num_threads(1)
    paths = providers(args.model, args.calibration, args.calibration_seed)
    instances = sample_instances(np.random.default_rng(args.seed), args.n)
    summarize(measure(paths, instances))
    print(f"torch threads {torch.get_num_threads()}")


if __name__ == "__main__":
    main()
