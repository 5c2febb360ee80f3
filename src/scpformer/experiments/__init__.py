"""Experiments: the papers' tables and figures, computed from solved instances and models.

One registry entry per paper table or figure (:data:`EXPERIMENTS`); ``scpformer experiment
list`` names them, ``scpformer experiment run NAME`` runs one into a folder holding a CSV of
per-instance results, PNG figures and ``report.md`` (:mod:`scpformer.experiments.runner`,
:mod:`scpformer.experiments.report`). The modules are imported when an experiment runs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from scpformer.experiments.runner import RunOptions, check_out_folder


@dataclass(frozen=True, kw_only=True)
class Experiment:
    """A registry entry: what it reproduces and where its ``run(options, command=...)`` lives."""

    name: str
    reproduces: str  # the paper table or figure
    summary: str
    module: str  # module defining run(options, *, command) -> Path of report.md
    default_n: int  # test instances at the default size (about 20 min on two cores)
    models: str  # what --model takes
    # Source paths (files, folders or git pathspecs, relative to the repository) whose code
    # decides the experiment's numbers. A committed result is stale when a commit after the
    # one it was measured at changed any of them: `git log --format=%H <commit>..HEAD --
    # <depends_on>` is non-empty (scpformer.experiments.summary.stale_commits). Report and
    # summary formatting are left out: they change no number.
    depends_on: tuple[str, ...] = ()

    def runner(self) -> Callable[..., Path]:
        """The experiment's ``run`` function."""
        return importlib.import_module(self.module).run


_ART = "ART paper (art-rendezvous-transformer.txt)"
_ROBUST = "robust ART paper (robust-art-chance-constrained.txt)"
_TSCVX = "T-SCvx paper (t-scvx-6dof-powered-descent.txt)"
# Source paths shared by several entries (an entry's own module is named in the entry).
_ART_NETWORK = (
    "src/scpformer/models/art.py",
    "src/scpformer/models/sequence.py",
    "src/scpformer/models/normalization.py",
)
_RENDEZVOUS_FAMILY = (
    "src/scpformer/problems/rendezvous",
    "src/scpformer/dynamics",
    "src/scpformer/data/rendezvous_family.py",
)
_ROBUST_FAMILY = (
    "src/scpformer/problems/robust_rendezvous",
    "src/scpformer/problems/rendezvous",
    "src/scpformer/dynamics",
    "src/scpformer/data/robust_rendezvous_family.py",
)
_FORECAST = ("src/scpformer/experiments/forecast_study.py", "src/scpformer/experiments/forecast.py")
_ART_FORECAST = (
    *_FORECAST,
    *_RENDEZVOUS_FAMILY,
    *_ART_NETWORK,
    "src/scpformer/warmstart/art.py",
    "src/scpformer/models/rnn.py",
)
_ROBUST_STUDY = (
    "src/scpformer/experiments/robust_studies.py",
    *_ROBUST_FAMILY,
    "src/scpformer/scp",
    "src/scpformer/warmstart",
    *_ART_NETWORK,
)
_TSCVX_SOLVE = (
    "src/scpformer/experiments/tscvx*",
    "src/scpformer/problems/pdg6dof",
    "src/scpformer/scp",
    "src/scpformer/warmstart/tscvx.py",
    "src/scpformer/models/tscvx.py",
    "src/scpformer/data/pdg6dof_family.py",
    "src/scpformer/data/tscvx_arrays.py",
)
EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment(
            name="art-forecast-tpbvp",
            reproduces=f"{_ART} Table 2",
            summary="ART/GRU/LSTM forecasts of Problem 1 (TPBVP) solutions (needs a tpbvp twin)",
            module="scpformer.experiments.forecast_study",
            default_n=200,
            models="ART, GRU and LSTM runs trained on Problem 1 twins",
            depends_on=_ART_FORECAST,
        ),
        Experiment(
            name="art-forecast-scp",
            reproduces=f"{_ART} Table 3",
            summary="ART/GRU/LSTM forecasts of Problem 3 (SCP) solutions",
            module="scpformer.experiments.forecast_study",
            default_n=200,
            models="ART, GRU and LSTM runs (any order; kinds read from the checkpoints)",
            depends_on=_ART_FORECAST,
        ),
        Experiment(
            name="robust-forecast",
            reproduces="ART paper Table 3's rows on the robust data",
            summary="robust ART's forecasts of the passively safe SCvx* solutions",
            module="scpformer.experiments.forecast_study",
            default_n=120,
            models="ART (and GRU/LSTM) runs trained on a robust-rendezvous dataset",
            depends_on=(
                *_FORECAST,
                *_ROBUST_FAMILY,
                "src/scpformer/scp",
                *_ART_NETWORK,
                "src/scpformer/warmstart/art.py",
            ),
        ),
        Experiment(
            name="art-conditioning",
            reproduces=f"{_ART} Fig. 3",
            summary="realized vs requested constraint-to-go and reward-to-go",
            module="scpformer.experiments.conditioning",
            default_n=40,
            models="one ART run",
            depends_on=(
                "src/scpformer/experiments/conditioning.py",
                *_RENDEZVOUS_FAMILY,
                *_ART_NETWORK,
                "src/scpformer/warmstart/art.py",
            ),
        ),
        Experiment(
            name="art-warmstart",
            reproduces=f"{_ART} Figs. 4-6",
            summary="SCP warm-started by CVX-TPBVP, CVX and ART, binned by C_CVX(t_1)",
            module="scpformer.experiments.warmstart_study",
            default_n=300,
            models="one ART run",
            depends_on=(
                "src/scpformer/experiments/warmstart_study.py",
                *_RENDEZVOUS_FAMILY,
                "src/scpformer/scp",
                "src/scpformer/warmstart",
                *_ART_NETWORK,
            ),
        ),
        Experiment(
            name="robust-warmstart",
            reproduces=f"{_ROBUST} Figs. 5-6",
            summary="PS-CVX/PS-ART, deterministic and chance-constrained, RTN and ROE models",
            module="scpformer.experiments.robust_studies",
            default_n=60,
            models="ART runs trained on RTN and on ROE states",
            depends_on=_ROBUST_STUDY,
        ),
        Experiment(
            name="robust-trajectory",
            reproduces=f"{_ROBUST} Figs. 7-8",
            summary="the instance with the largest ART gain: warm starts, drift arcs, Eq. 15",
            module="scpformer.experiments.robust_studies",
            default_n=30,
            models="ART runs trained on RTN and/or ROE states (one per frame)",
            depends_on=_ROBUST_STUDY,
        ),
        Experiment(
            name="robust-posthoc",
            reproduces=f"{_ROBUST} Figs. 9-10",
            summary="E_R and E_C of the post hoc check and the SCP outcome with/without it",
            module="scpformer.experiments.robust_studies",
            default_n=60,
            models="ART runs trained on RTN and/or ROE states (one per frame)",
            depends_on=(*_ROBUST_STUDY, "src/scpformer/experiments/robust_posthoc.py"),
        ),
        Experiment(
            name="mpc-rendezvous",
            reproduces="Celestini et al. (RA-L 2024), closed-loop MPC: warm-start gains",
            summary="closed-loop rendezvous Monte Carlo: cold, previous, ART and best re-plans",
            module="scpformer.experiments.mpc_rendezvous",
            default_n=100,  # about 22 min on two busy cores (22:16 measured at load 5-6)
            models="the shipped art-rendezvous model, started mid-horizon",
            depends_on=(
                "src/scpformer/experiments/mpc_rendezvous.py",
                "src/scpformer/guidance",
                *_RENDEZVOUS_FAMILY,
                "src/scpformer/scp",
            ),
        ),
        Experiment(
            name="mpc-robust-rendezvous",
            reproduces="closed-loop MPC of the chance-constrained, passively safe rendezvous",
            summary="closed-loop robust rendezvous Monte Carlo: cold vs previous-plan re-plans",
            module="scpformer.experiments.mpc_robust_rendezvous",
            default_n=100,
            models="none (the classical starts; the learned one flies in simulate)",
            depends_on=(
                "src/scpformer/experiments/mpc_robust_rendezvous.py",
                "src/scpformer/guidance",
                *_ROBUST_FAMILY,
                "src/scpformer/scp",
            ),
        ),
        Experiment(
            name="mpc-pdg6dof",
            reproduces="closed-loop 6-DoF landing: T-SCvx against the classical re-plan starts",
            summary="closed-loop landing Monte Carlo: cold, previous-plan and T-SCvx re-plans",
            module="scpformer.experiments.mpc_pdg6dof",
            default_n=100,
            models="the shipped T-SCvx networks",
            depends_on=(
                "src/scpformer/experiments/mpc_pdg6dof.py",
                "src/scpformer/guidance",
                "src/scpformer/problems/pdg6dof",
                "src/scpformer/scp",
            ),
        ),
        Experiment(
            name="tscvx-training",
            reproduces=f"{_TSCVX} Table 3",
            summary="T-SCvx networks: losses, test accuracy vs all-zeros/ones, precision/recall",
            module="scpformer.experiments.tscvx",
            default_n=1,
            models="one T-SCvx run (scpformer train tscvx)",
            depends_on=(
                "src/scpformer/experiments/tscvx*",
                "src/scpformer/experiments/prediction_metrics.py",
                "src/scpformer/models/tscvx.py",
                "src/scpformer/train",
                "src/scpformer/data/tscvx_arrays.py",
                "src/scpformer/data/pdg6dof_family.py",
                "src/scpformer/data/augment.py",
                "src/scpformer/problems/pdg6dof",
            ),
        ),
        Experiment(
            name="tscvx-solve-time",
            reproduces=f"{_TSCVX} Fig. 2",
            summary="cold SCvx vs T-SCvx solve times, converged rates, propellant gaps",
            module="scpformer.experiments.tscvx",
            default_n=100,
            models="one T-SCvx run",
            depends_on=(*_TSCVX_SOLVE, "src/scpformer/pretrained/tscvx"),
        ),
        Experiment(
            name="tscvx-trajectory",
            reproduces=f"{_TSCVX} Fig. 3",
            summary="a T-SCvx solution and its predicted vs true tight rows",
            module="scpformer.experiments.tscvx",
            default_n=1,
            models="one T-SCvx run",
            depends_on=(*_TSCVX_SOLVE, "src/scpformer/pretrained/tscvx"),
        ),
        Experiment(
            name="tscvx-lookup",
            reproduces=f"{_TSCVX} Tables 4-5, Fig. 4",
            summary="networks vs k-d tree vs interpolation: time, MSE, OOD MSE, memory, solves",
            module="scpformer.experiments.tscvx",
            default_n=60,
            models="a T-SCvx run, a kdtree run and an interp run",
            depends_on=(
                *_TSCVX_SOLVE,
                "src/scpformer/experiments/prediction_metrics.py",
                "src/scpformer/models/lookup.py",
            ),
        ),
    )
}


def get_experiment(name: str) -> Experiment:
    """The registry entry ``name`` (``ValueError`` listing the names otherwise)."""
    if name not in EXPERIMENTS:
        raise ValueError(f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}")
    return EXPERIMENTS[name]


def run_experiment(name: str, options: RunOptions, command: str = "") -> Path:
    """Run experiment ``name``; returns the path of its ``report.md``."""
    experiment = get_experiment(name)
    check_out_folder(options.out)
    run: Any = experiment.runner()
    if options.n is None:
        options = replace(options, n=experiment.default_n)
    return run(options, command=command, name=name)


__all__ = ["EXPERIMENTS", "Experiment", "RunOptions", "get_experiment", "run_experiment"]
