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
_TSCVX_SHIPPED = (*_TSCVX_SOLVE, "src/scpformer/pretrained/tscvx")
_SCP = "src/scpformer/scp"
#: What every closed-loop experiment runs: the campaign, its records, the shared report
#: tables; each adds its family's loop (``_GUIDANCE_*``).
_CLOSED_LOOP = (
    "src/scpformer/guidance/__init__.py",
    "src/scpformer/guidance/campaign.py",
    "src/scpformer/guidance/records.py",
    "src/scpformer/experiments/closed_loop.py",
    "src/scpformer/experiments/paired.py",
)
_GUIDANCE_RENDEZVOUS = (
    *_CLOSED_LOOP,
    "src/scpformer/guidance/rendezvous_mpc.py",
    "src/scpformer/guidance/rendezvous_art.py",
    "src/scpformer/warmstart/art.py",
)
_GUIDANCE_ROBUST = (*_GUIDANCE_RENDEZVOUS, "src/scpformer/guidance/robust_rendezvous_mpc.py")
_GUIDANCE_PDG6DOF = (
    *_CLOSED_LOOP,
    "src/scpformer/guidance/pdg6dof_mpc.py",
    "src/scpformer/guidance/pdg6dof_tracking.py",
    "src/scpformer/warmstart/tscvx.py",
)
_ROWS: tuple[tuple[str, str, str, str, int, str, tuple[str, ...]], ...] = (
    # name, reproduces, summary, module (in this package), default_n, models, depends_on
    ("art-forecast-tpbvp", f"{_ART} Table 2",
     "ART/GRU/LSTM forecasts of Problem 1 (TPBVP) solutions (needs a tpbvp twin)",
     "forecast_study", 200, "ART, GRU and LSTM runs trained on Problem 1 twins", _ART_FORECAST),
    ("art-forecast-scp", f"{_ART} Table 3", "ART/GRU/LSTM forecasts of Problem 3 (SCP) solutions",
     "forecast_study", 200,
     "ART, GRU and LSTM runs (any order; kinds read from the checkpoints)", _ART_FORECAST),
    ("robust-forecast", "ART paper Table 3's rows on the robust data",
     "robust ART's forecasts of the passively safe SCvx* solutions", "forecast_study", 120,
     "ART (and GRU/LSTM) runs trained on a robust-rendezvous dataset",
     (*_FORECAST, *_ROBUST_FAMILY, _SCP, *_ART_NETWORK, "src/scpformer/warmstart/art.py")),
    ("art-conditioning", f"{_ART} Fig. 3",
     "realized vs requested constraint-to-go and reward-to-go", "conditioning", 40, "one ART run",
     ("src/scpformer/experiments/conditioning.py", *_RENDEZVOUS_FAMILY, *_ART_NETWORK,
      "src/scpformer/warmstart/art.py")),
    ("art-warmstart", f"{_ART} Figs. 4-6",
     "SCP warm-started by CVX-TPBVP, CVX and ART, binned by C_CVX(t_1)", "warmstart_study", 300,
     "one ART run",
     ("src/scpformer/experiments/warmstart_study.py", *_RENDEZVOUS_FAMILY, _SCP,
      "src/scpformer/warmstart", *_ART_NETWORK)),
    ("robust-warmstart", f"{_ROBUST} Figs. 5-6",
     "PS-CVX/PS-ART, deterministic and chance-constrained, RTN and ROE models",
     "robust_studies", 60, "ART runs trained on RTN and on ROE states", _ROBUST_STUDY),
    ("robust-trajectory", f"{_ROBUST} Figs. 7-8",
     "the instance with the largest ART gain: warm starts, drift arcs, Eq. 15", "robust_studies",
     30, "ART runs trained on RTN and/or ROE states (one per frame)", _ROBUST_STUDY),
    ("robust-posthoc", f"{_ROBUST} Figs. 9-10",
     "E_R and E_C of the post hoc check and the SCP outcome with/without it", "robust_studies",
     60, "ART runs trained on RTN and/or ROE states (one per frame)",
     (*_ROBUST_STUDY, "src/scpformer/experiments/robust_posthoc.py")),
    ("mpc-rendezvous", "Celestini et al. (RA-L 2024), closed-loop MPC: warm-start gains",
     "closed-loop rendezvous Monte Carlo: cold, previous, ART and best re-plans",
     "mpc_rendezvous", 100,  # about 22 min on two busy cores (22:16 measured at load 5-6)
     "the shipped art-rendezvous model, started mid-horizon",
     ("src/scpformer/experiments/mpc_rendezvous.py", *_GUIDANCE_RENDEZVOUS,
      *_RENDEZVOUS_FAMILY, _SCP)),
    ("mpc-robust-rendezvous",
     "closed-loop MPC of the chance-constrained, passively safe rendezvous",
     "closed-loop robust rendezvous Monte Carlo: cold, previous, robust ART and best re-plans",
     "mpc_robust_rendezvous", 100,
     "the shipped art-robust model, started mid-horizon",
     ("src/scpformer/experiments/mpc_robust_rendezvous.py", *_GUIDANCE_ROBUST,
      *_ROBUST_FAMILY, _SCP)),
    ("mpc-pdg6dof", "closed-loop 6-DoF landing: T-SCvx against the classical re-plan starts",
     "closed-loop landing Monte Carlo: cold, previous, T-SCvx and best re-plans",
     "mpc_pdg6dof", 100, "the shipped tscvx-midflight networks",
     ("src/scpformer/experiments/mpc_pdg6dof.py", *_GUIDANCE_PDG6DOF,
      "src/scpformer/problems/pdg6dof", _SCP)),
    ("tscvx-training", f"{_TSCVX} Table 3",
     "T-SCvx networks: losses, test accuracy vs all-zeros/ones, precision/recall", "tscvx", 1,
     "one T-SCvx run (scpformer train tscvx)",
     ("src/scpformer/experiments/tscvx*", "src/scpformer/experiments/prediction_metrics.py",
      "src/scpformer/models/tscvx.py", "src/scpformer/train", "src/scpformer/data/tscvx_arrays.py",
      "src/scpformer/data/pdg6dof_family.py", "src/scpformer/data/augment.py",
      "src/scpformer/problems/pdg6dof")),
    ("tscvx-solve-time", f"{_TSCVX} Fig. 2",
     "cold SCvx vs T-SCvx solve times, converged rates, propellant gaps", "tscvx", 100,
     "one T-SCvx run", _TSCVX_SHIPPED),
    ("tscvx-trajectory", f"{_TSCVX} Fig. 3",
     "a T-SCvx solution and its predicted vs true tight rows", "tscvx", 1, "one T-SCvx run",
     _TSCVX_SHIPPED),
    ("tscvx-lookup", f"{_TSCVX} Tables 4-5, Fig. 4",
     "networks vs k-d tree vs interpolation: time, MSE, OOD MSE, memory, solves", "tscvx", 60,
     "a T-SCvx run, a kdtree run and an interp run",
     (*_TSCVX_SOLVE, "src/scpformer/experiments/prediction_metrics.py",
      "src/scpformer/models/lookup.py")),
)  # fmt: skip


def _entry(
    name: str,
    reproduces: str,
    summary: str,
    module: str,
    default_n: int,
    models: str,
    depends_on: tuple[str, ...],
) -> Experiment:
    """The registry entry of one row of :data:`_ROWS` (``module`` named within this package)."""
    return Experiment(name=name, reproduces=reproduces, summary=summary,
                      module=f"{__name__}.{module}", default_n=default_n, models=models,
                      depends_on=depends_on)  # fmt: skip


EXPERIMENTS: dict[str, Experiment] = {row[0]: _entry(*row) for row in _ROWS}


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
