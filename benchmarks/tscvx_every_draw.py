"""T-SCvx against cold SCvx on every draw of a fresh seed, draws with no landing included.

Draws ``--n`` instances of the feasible sampler (``PDGSampleRanges.feasible``) with
``--seed`` -- pick a seed no dataset, training run or setting was chosen on -- and solves
each with ``scpformer.pdg6dof.solve`` twice, ``method="scvx"`` (cold, the cubic profile) and
``method="tscvx"`` (the shipped networks, or ``--model``), alternating which goes first, one
torch thread, verification on. Each time is the wall time of the whole call: network
inference, every conic solve, fallbacks, the nonlinear check.

Prints the success counts, the mean and median times of each method over all draws and
their ratios, the median per-draw ratio, per-draw win / tie / loss (a tie is within 5%),
the ratios on the draws both solve, and one line per draw that either fails. Rows are
appended to ``--out`` (JSON lines) as they finish; a rerun with the same file skips the
draws already in it.

``--ranges outside`` draws instead from Table 2's ranges around the feasible box (altitude
1.5-10, East/North 0-10, velocity -2-0 up and +-2 across, the other parameters as the
feasible preset, with its consistency and propellant checks) and keeps only the draws with
an initial position or velocity outside the feasible box: instances unlike any the networks
were trained on, but inside Table 2.

Usage: python benchmarks/tscvx_every_draw.py --seed 31337 --n 40 [--model RUN]
       [--ranges feasible|outside] [--out tscvx-every-draw.jsonl]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
import torch

import scpformer.pdg6dof as pdg
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances

TIE = 1.05  # per-draw time ratios within this factor are ties


def outside_box(instance: PDGInstance, box: PDGSampleRanges) -> bool:
    """Whether the initial position or velocity lies outside the sampler's box."""
    state = [*instance.r0, *instance.v0]
    bounds = [*box.r0, *box.v0]
    return any(not lo <= value <= hi for value, (lo, hi) in zip(state, bounds, strict=True))


def draw_instances(seed: int, n: int, ranges: str) -> list[PDGInstance]:
    """``n`` draws of the feasible sampler, or of the ``outside`` ranges (module docstring)."""
    rng = np.random.default_rng(seed)
    box = PDGSampleRanges.feasible()
    if ranges == "feasible":
        return sample_instances(rng, n, box)
    wide = dataclasses.replace(
        box,
        r0=((1.5, 10.0), (0.0, 10.0), (0.0, 10.0)),
        v0=((-2.0, -0.1), (-2.0, 2.0), (-2.0, 2.0)),
    )
    found: list[PDGInstance] = []
    while len(found) < n:
        found += [i for i in sample_instances(rng, n, wide) if outside_box(i, box)]
    return found[:n]


def solve_row(instance, method: str, warmstart) -> dict:
    start = time.perf_counter()
    solution = pdg.solve(instance, method=method, warmstart=warmstart)
    wall = time.perf_counter() - start
    tscvx = solution.extras.get("tscvx") or {}
    return {
        "wall_s": wall,
        "status": solution.status.value,
        "converged": solution.converged,
        "conic_solves": solution.iterations,
        "fallback": tscvx.get("fallback"),
    }


def measure(args: argparse.Namespace, done: set[int]) -> None:
    warmstart = None
    if args.model is not None:
        from scpformer.warmstart.tscvx import TscvxWarmStart

        warmstart = TscvxWarmStart.from_checkpoint(args.model)
    instances = draw_instances(args.seed, args.n, args.ranges)
    pdg.solve(instances[0], method="tscvx", warmstart=warmstart, verify=False)  # load, compile
    with args.out.open("a") as fh:
        for index, instance in enumerate(instances):
            if index in done:
                continue
            order = ("scvx", "tscvx") if index % 2 == 0 else ("tscvx", "scvx")
            row = {"seed": args.seed, "ranges": args.ranges, "draw": index}
            for method in order:
                row[method] = solve_row(instance, method, warmstart if method == "tscvx" else None)
            fh.write(json.dumps(row) + "\n")
            fh.flush()
            print(
                f"draw {index}: cold {row['scvx']['status']} {row['scvx']['wall_s']:.2f} s, "
                f"T-SCvx {row['tscvx']['status']} {row['tscvx']['wall_s']:.2f} s",
                flush=True,
            )


def summarize(rows: list[dict]) -> None:
    cold = np.array([r["scvx"]["wall_s"] for r in rows])
    tscvx = np.array([r["tscvx"]["wall_s"] for r in rows])
    cold_ok = np.array([r["scvx"]["converged"] for r in rows])
    tscvx_ok = np.array([r["tscvx"]["converged"] for r in rows])
    both = cold_ok & tscvx_ok
    ratio = cold / tscvx
    print(
        f"{len(rows)} draws: cold SCvx converged on {cold_ok.sum()}, T-SCvx on "
        f"{tscvx_ok.sum()} (both {both.sum()}, cold only {(cold_ok & ~tscvx_ok).sum()}, "
        f"T-SCvx only {(tscvx_ok & ~cold_ok).sum()})"
    )
    print(
        f"all draws: mean {cold.mean():.3f} s cold, {tscvx.mean():.3f} s T-SCvx "
        f"({cold.mean() / tscvx.mean():.2f}x); median {np.median(cold):.3f} s, "
        f"{np.median(tscvx):.3f} s ({np.median(cold) / np.median(tscvx):.2f}x); "
        f"median per-draw ratio {np.median(ratio):.2f}x"
    )
    wins, losses = int((ratio > TIE).sum()), int((ratio < 1 / TIE).sum())
    print(f"per draw T-SCvx faster / tie / slower: {wins} / {len(rows) - wins - losses} / {losses}")
    if both.any():
        print(
            f"draws both solve: mean {cold[both].mean() / tscvx[both].mean():.2f}x, "
            f"median per-draw {np.median(ratio[both]):.2f}x"
        )
    for r in rows:
        if not (r["scvx"]["converged"] and r["tscvx"]["converged"]):
            c, t = r["scvx"], r["tscvx"]
            print(
                f"  draw {r['draw']}: cold {c['status']} after {c['conic_solves']} solves "
                f"({c['wall_s']:.2f} s); T-SCvx {t['status']} after {t['conic_solves']} "
                f"({t['wall_s']:.2f} s, fallback {t['fallback']})"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, required=True, help="sampler seed (a fresh one)")
    parser.add_argument("--n", type=int, default=40, help="draws (default: 40)")
    parser.add_argument("--model", type=Path, help="T-SCvx run folder (default: shipped)")
    parser.add_argument("--ranges", choices=("feasible", "outside"), default="feasible")
    parser.add_argument("--out", type=Path, default=Path("tscvx-every-draw.jsonl"))
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    if args.out.exists():
        rows = [json.loads(line) for line in args.out.read_text().splitlines() if line]
        rows = [r for r in rows if r["seed"] == args.seed and r.get("ranges") == args.ranges]
    measure(args, {r["draw"] for r in rows})
    rows = [json.loads(line) for line in args.out.read_text().splitlines() if line]
    mine = [r for r in rows if r["seed"] == args.seed and r.get("ranges") == args.ranges]
    summarize(sorted(mine, key=lambda r: r["draw"]))
    print(f"torch threads {torch.get_num_threads()}")


if __name__ == "__main__":
    main()
