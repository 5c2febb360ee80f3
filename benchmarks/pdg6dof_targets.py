"""Check the 6-DoF performance targets on this machine.

Runs ``scpformer bench pdg6dof`` (20 nominal + 10 Table 2 instances, seed 0) and compares
the nominal set with the targets: median wall time under 1 s, at least 70% of the wall
time inside the conic solver, every instance converged, and median / p95 subproblem solves
at most 15 / 25. Prints the summary and PASS/FAIL per target; exit status 1 on a
miss. Timings depend on the machine and its load: run it on an otherwise idle machine.

Usage: python benchmarks/pdg6dof_targets.py [--csv bench_pdg6dof.csv]
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys

import numpy as np

TARGET_MEDIAN_S = 1.0
TARGET_SOLVER_SHARE = 0.70
TARGET_MEDIAN_SOLVES = 15
TARGET_P95_SOLVES = 25


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", default="bench_pdg6dof.csv")
    args = parser.parse_args()
    subprocess.run(["scpformer", "bench", "pdg6dof", "--csv", args.csv], check=True)
    with open(args.csv, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["set"] == "nominal"]
    wall = np.array([float(r["wall_s"]) for r in rows])
    share = sum(float(r["solver_s"]) for r in rows) / wall.sum()
    solves = np.array([float(r["iterations"]) for r in rows])
    converged = sum(r["status"] == "converged" for r in rows)
    checks = [
        (
            f"median wall time {np.median(wall):.3f} s < {TARGET_MEDIAN_S} s",
            np.median(wall) < TARGET_MEDIAN_S,
        ),
        (
            f"conic solver share {share:.0%} >= {TARGET_SOLVER_SHARE:.0%}",
            share >= TARGET_SOLVER_SHARE,
        ),
        (f"converged {converged} of {len(rows)}", converged == len(rows)),
        (
            f"median solves {np.median(solves):.1f} <= {TARGET_MEDIAN_SOLVES}",
            np.median(solves) <= TARGET_MEDIAN_SOLVES,
        ),
        (
            f"p95 solves {np.percentile(solves, 95):.1f} <= {TARGET_P95_SOLVES}",
            np.percentile(solves, 95) <= TARGET_P95_SOLVES,
        ),
    ]
    for text, ok in checks:
        print(("PASS " if ok else "FAIL ") + text)
    return 0 if all(ok for _, ok in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
