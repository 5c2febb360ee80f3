"""How exactly must ART imitate the passively safe optimum for its guess to pass Eq. 8?

For ``--n`` converged samples of a chance-constrained robust dataset (``scpformer generate
robust-rendezvous --mode chance``), the optimal impulses of the kept trajectory (twin ``ps``)
are rolled out from the initial state the way ART's Algorithm 2 rolls out its own:

- through the J2 STM (the paper's Eq. 1, what the rollout used before it followed the plan's
  dynamics) and through the plan's dynamics (``plan_step``: the nonlinear mean-element flow
  the datasets' trajectories obey), each with the optimal impulses unchanged;
- through the plan's dynamics with each impulse perturbed by isotropic Gaussian noise of
  ``--noise`` times its norm (open loop: unlike ART, nothing corrects the drift, so this is a
  pessimistic model of an imitation error of that relative size).

Each rolled-out trajectory is put through the post hoc check (robust paper, Eq. 8, with the
paper's window, ``AcceptanceCheck``; ``R_des = -J_TPBVP`` from the sample's ``cvx`` twin,
``C_des = 0``); ``C`` is the Eq. 7 budget of the trajectory in the plan's dynamics. Prints, per
rollout, the median ``E_C``, the share with ``E_C <= 2``, the median ``100 E_R``, the share
accepted and the median distance of the final state from the optimum's.

Usage: python benchmarks/robust_art_rollout_model.py --data DATASET [--n 200]
       [--noise 0.001 0.003 0.01 0.03] [--seed 0]
"""

from __future__ import annotations

import argparse

import numpy as np

from scpformer.data.reader import ShardedSamples
from scpformer.data.robust_rendezvous_family import instance_from_theta
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.problems.robust_rendezvous.plan_dynamics import plan_step
from scpformer.problems.robust_rendezvous.safety import trajectory_violations
from scpformer.warmstart.art import AcceptanceCheck


def rollout(instance, model, x0: np.ndarray, u: np.ndarray, dynamics: str) -> np.ndarray:
    """States (N+1, 6) [m] of impulses ``u`` (N, 3) from ``x0`` in ``dynamics``."""
    x = [x0[None]]
    for k in range(u.shape[0]):
        x.append(plan_step(instance, model, k, x[-1], u[[k]], dynamics)[0])
    return np.concatenate(x)


def row(instance, x: np.ndarray, u: np.ndarray, j_tpbvp: float, x_end: np.ndarray) -> tuple:
    """(E_C, 100 E_R, accepted, final-state distance [m]) of a rolled-out guess."""
    ctg = float(trajectory_violations(instance, x, u, "chance")[0])
    cost = float(np.linalg.norm(u, axis=1).sum())
    decision = AcceptanceCheck().evaluate(
        rtg_desired=-j_tpbvp, ctg_desired=0.0, rtg_realized=-cost, ctg_realized=ctg
    )
    return decision.E_C, 100.0 * decision.E_R, decision.accepted, np.abs(x[-1] - x_end).max()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="chance-constrained robust dataset folder")
    parser.add_argument("--n", type=int, default=200, help="converged samples to use")
    parser.add_argument("--noise", type=float, nargs="+", default=[0.001, 0.003, 0.01, 0.03])
    parser.add_argument("--seed", type=int, default=0, help="seed of the impulse noise")
    args = parser.parse_args()
    data, rng = ShardedSamples(args.data), np.random.default_rng(args.seed)
    cases = ["optimum, STM", "optimum, plan dynamics", *(f"noise {e:g}" for e in args.noise)]
    rows: dict[str, list[tuple]] = {case: [] for case in cases}
    used = 0
    for i in range(len(data)):
        if used == args.n:
            break
        if data.read("status", i) != "converged" or data.read("mode", i) != "chance":
            continue
        used += 1
        instance = instance_from_theta(data.read("theta", i))
        model = linear_model(instance)
        x_opt, u_opt = data.read("ps_roe", i), data.read("ps_dv", i)
        j_tpbvp = float(data.read("cvx_cost", i))
        for case, dynamics in zip(cases[:2], ("stm", "nonlinear"), strict=True):
            x = rollout(instance, model, x_opt[0], u_opt, dynamics)
            rows[case].append(row(instance, x, u_opt, j_tpbvp, x_opt[-1]))
        scale = np.linalg.norm(u_opt, axis=1, keepdims=True)
        for case, e in zip(cases[2:], args.noise, strict=True):
            u = u_opt + e * scale * rng.standard_normal(u_opt.shape)
            x = rollout(instance, model, x_opt[0], u, "nonlinear")
            rows[case].append(row(instance, x, u, j_tpbvp, x_opt[-1]))
    print(f"{used} converged chance-mode samples of {args.data}")
    header = ("rollout", "E_C median", "E_C <= 2", "100 E_R median", "accepted",
              "final-state gap median")  # fmt: skip
    print("| " + " | ".join(header) + " |\n|" + " --- |" * len(header))
    for case in cases:
        a = np.array(rows[case], dtype=float)
        cells = (case, f"{np.median(a[:, 0]):g}", f"{np.mean(a[:, 0] <= 2):.0%}",
                 f"{np.median(a[:, 1]):.2f}", f"{np.mean(a[:, 2]):.0%}",
                 f"{np.median(a[:, 3]):.3g} m")  # fmt: skip
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
