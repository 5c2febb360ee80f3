"""Truth-replay terminal miss of robust rendezvous plans (issue 10, point 3).

Samples ``--n`` Table 1 instances (``--seed``), solves each with the three-stage procedure in
``--mode``, replays the impulses through the two-body + J2 propagator from the package's
osculating initial state (:func:`scpformer.problems.robust_rendezvous.problem.replay`) and
prints the waypoint miss per instance with median and max. ``--save`` writes the impulses so
that a plan made by one version of the code can be replayed by another (``--load``: skip the
solve and replay the saved impulses).

Usage: python benchmarks/robust_truth_replay.py [--n 20] [--seed 0] [--save plans.npz]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from scpformer.problems.robust_rendezvous.instance import sample_instances
from scpformer.problems.robust_rendezvous.problem import replay, solve


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--mode", default="chance")
    parser.add_argument("--save", help="write the impulses of every plan to this .npz")
    parser.add_argument("--load", help="replay the impulses of this .npz instead of solving")
    args = parser.parse_args()
    instances = sample_instances(args.seed, args.n)
    plans = dict(np.load(args.load)) if args.load else {}
    misses, saved = [], {}
    for k, instance in enumerate(instances):
        start = time.perf_counter()
        if args.load:
            u, label = plans[f"u{k}"], "loaded"
        else:
            sol = solve(instance, mode=args.mode)
            if sol.trajectory is None:
                print(f"{k:3d} {instance.waypoint} no trajectory ({sol.status.value})")
                continue
            u = sol.trajectory.u
            label = f"{sol.status.value} stage={sol.extras.get('stage')} "
            label += f"dynamics={sol.extras.get('dynamics', 'stm')}"
        saved[f"u{k}"] = u
        truth = replay(instance, u)
        miss = float(np.linalg.norm(truth.rtn[-1, :3] - instance.xf_rtn[:3]))
        misses.append(miss)
        print(f"{k:3d} {instance.waypoint:>2} miss {miss:8.2f} m  {label} "
              f"({time.perf_counter() - start:.1f} s)", flush=True)  # fmt: skip
    if args.save:
        np.savez(args.save, **saved)
    m = np.array(misses)
    print(f"terminal miss over {m.size} plans: median {np.median(m):.2f} m, "
          f"max {m.max():.2f} m, > 5 m: {int(np.sum(m > 5.0))}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
