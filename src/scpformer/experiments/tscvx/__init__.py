"""T-SCvx experiments (T-SCvx paper Sec. IV): Table 3, Figs. 2-4 and Tables 4-5.

=====================  ========================================================================
experiment             what it runs
=====================  ========================================================================
``tscvx-training``     Table 3: the networks' training and validation losses (``RUN/*/
                       metrics.csv``), test accuracy beside the all-zeros/all-ones baselines,
                       precision and recall of the tight rows per constraint, solution MSE
``tscvx-solve-time``   Fig. 2: cold SCvx and T-SCvx (Algorithm 2) on the same test instances,
                       in the same worker, one after the other: solve-time box plots, converged
                       rates, propellant gaps to cold SCvx's optimum
``tscvx-trajectory``   Fig. 3: one T-SCvx solution with its thrust vectors, and the rows
                       predicted tight beside the rows tight in the cold SCvx run
``tscvx-lookup``       Tables 4-5 and Fig. 4: inference time, MSE, OOD MSE and memory of the
                       networks and of the lookup tables (:mod:`scpformer.models.lookup`); and,
                       beyond the paper, T-SCvx run with each of them on in-distribution and on
                       OOD test instances
=====================  ========================================================================

``--model`` takes T-SCvx runs (``scpformer train tscvx``) and lookup runs (``scpformer train
kdtree|interp``), told apart by :func:`scpformer.models.predictors.predictor_kind`. Solve
times are wall times of the whole call, network or table inference included, with one torch
thread per worker. The solves of one instance run in one worker, one after the other, in an
order that alternates between instances so that no method always runs on a warmer cache.
"""

from __future__ import annotations

from pathlib import Path

from scpformer.experiments.runner import RunOptions
from scpformer.experiments.tscvx.lookup import run_lookup
from scpformer.experiments.tscvx.solve_time import run_solve_time
from scpformer.experiments.tscvx.training import run_training
from scpformer.experiments.tscvx.trajectory import run_trajectory


def run(options: RunOptions, *, command: str = "", name: str = "tscvx-solve-time") -> Path:
    """Run one of the T-SCvx experiments into ``options.out``; returns the report's path."""
    runners = {
        "tscvx-training": run_training,
        "tscvx-solve-time": run_solve_time,
        "tscvx-trajectory": run_trajectory,
        "tscvx-lookup": run_lookup,
    }
    if name not in runners:
        raise ValueError(f"unknown T-SCvx experiment {name!r}")
    return runners[name](options, command=command, name=name)
