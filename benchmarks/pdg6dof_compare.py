"""Compare two ``scpformer bench pdg6dof`` CSV files instance by instance (before / after).

The ``after`` file must come from ``bench pdg6dof --optimality``: its reference cost is the
yardstick of both columns, so the ``before`` solutions (e.g. from another branch, run on the
same seed) are measured against the same local optimum. Prints, per nominal instance, the
status, the subproblem solves and the propellant gap of each, then medians, p95 and max.

Usage: python benchmarks/pdg6dof_compare.py BEFORE.csv AFTER.csv --seed 0
"""

from __future__ import annotations

import argparse
import csv
import sys

import numpy as np

from scpformer.problems.pdg6dof.problem import propellant_gap
from scpformer.problems.pdg6dof.sampling import PDGSampleRanges, sample_instances


def read_nominal(path: str) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return [row for row in csv.DictReader(fh) if row["set"] == "nominal"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--seed", type=int, default=0, help="the seed both benches used")
    args = parser.parse_args()
    before, after = read_nominal(args.before), read_nominal(args.after)
    if len(before) != len(after):
        raise SystemExit(f"error: {len(before)} nominal rows before, {len(after)} after")
    instances = sample_instances(
        np.random.default_rng(args.seed), len(after), PDGSampleRanges.nominal()
    )
    print(f"{'#':>3} {'before':<15} {'it':>3} {'gap':>7} | {'after':<15} {'it':>3} {'gap':>7}")
    gaps: dict[str, list[float]] = {"before": [], "after": []}
    for inst, b, a in zip(instances, before, after, strict=True):
        reference = float(a["reference_cost"])
        gb = propellant_gap(inst, float(b["cost"]), reference)
        ga = propellant_gap(inst, float(a["cost"]), reference)
        gaps["before"].append(gb)
        gaps["after"].append(ga)
        print(
            f"{a['index']:>3} {b['status']:<15} {b['iterations']:>3} {gb:>7.2%} | "
            f"{a['status']:<15} {a['iterations']:>3} {ga:>7.3%}"
        )
    for name, rows in (("before", before), ("after", after)):
        its = np.array([float(r["iterations"]) for r in rows])
        conv = sum(r["status"] == "converged" for r in rows)
        g = np.array(gaps[name])
        print(
            f"{name:<6}: converged {conv}/{len(rows)}, solves median {np.median(its):.1f} "
            f"p95 {np.percentile(its, 95):.1f}, gap median {np.median(g):.3%} max {g.max():.3%}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
