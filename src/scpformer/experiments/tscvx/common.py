"""What the T-SCvx experiments share: their inputs (dataset, runs, solver configuration),
the per-instance work (cold SCvx and T-SCvx with each predictor, timed in one worker) and
the analysis of a solve study (statistics, box plots, comparisons with the paper)."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.paired import Outcomes, paired_table
from scpformer.experiments.runner import (
    KEY,
    RESULTS_NAME,
    InstanceTask,
    ResultsCSV,
    RunOptions,
    check_settings,
    column,
    dataset_commands,
    require_data,
    require_models,
    result_columns,
    run_tasks,
    settings_dict,
    theta_tasks,
)
from scpformer.models.predictors import predictor_kind

PAPER = "T-SCvx paper (t-scvx-6dof-powered-descent.txt)"
COLD = "cold"  # cold SCvx from the straight-line guess
#: One paper-vs-ours row: quantity, the paper's number, ours and optionally a note.
ComparisonRow = tuple[str, str, str] | tuple[str, str, str, str]
PER_METHOD = (
    "status",
    "time_s",
    "iterations",
    "cost",
    "verified",
    "gap",
    "fallback",
    "rows_kept",
    "guess_accepted",
)
TSCVX_DIFFERENCES: tuple[str, ...] = (
    "Dataset and networks: the paper trains on about 12,000 samples (with rotations) with "
    "8.91 M / 9 M-parameter networks on a GPU; ours are the dataset and preset named in the "
    "commands above, trained on two CPU cores.",
    "Inputs: our networks see each instance in its canonical frame (yawed about Up so that "
    "r0 has no North component, the body rolled so that q0 has no twist about body x; both "
    "exact symmetries of the problem, scpformer.problems.pdg6dof.symmetry) and the solution "
    "network predicts there, mapped back exactly; the paper feeds the raw parameters and "
    "relies on the rotation augmentation alone (train tscvx --no-canonical trains that way, "
    "for a comparison; no committed result measures the frame's effect).",
    "Stall test: our SCvx stops a run whose penalty stays above 1e-3 and falls less than 2% "
    "in 15 accepted iterations (status 'stalled'), and restarts a stalled cold solve once "
    "with a longer final time; the paper runs to its iteration limit.",
    "Formulation: SCvx as configured here (soft quadratic trust region, "
    "second-order correction, stopping on the predicted decrease, iter_max 100) on N = 50 "
    "nodes; the paper's Table 1 SCvx (hard trust region, 20 iterations) stops earlier and "
    "further from the optimum, so its SCvx solve times are not ours.",
    "Inequality rows: 7 names x N nodes (mass, glideslope, tilt, omega, thrust_min, "
    "thrust_max, gimbal); the paper's classifier outputs 12 N flags.",
    "Conic solver: Clarabel on the compiled conic data, the reduced subproblem sliced from it "
    "(no cvxpy canonicalization per iteration); the paper uses cvxpy with ECOS/MOSEK.",
    "Virtual control: T-SCvx's reduced solves leave nu and the safeguard box out unless the "
    "last solve needed nu, and check that the dynamics multipliers stay below lambda (else "
    "they are repeated with nu); cold SCvx always keeps nu, as Algorithm 1.",
)


# ======================================================================================
# inputs
# ======================================================================================
@dataclass(frozen=True)
class TscvxStudy:
    """A checked ``pdg6dof`` dataset and the predictor runs of ``--model``, by kind."""

    data: Path
    config: dict[str, Any]  # the dataset manifest's family configuration
    runs: dict[str, Path]  # kind (tscvx, kdtree, interp) -> run folder

    def only(self, *kinds: str) -> TscvxStudy:
        """This study with the runs of ``kinds`` alone."""
        return TscvxStudy(self.data, self.config, {kind: self.runs[kind] for kind in kinds})

    def provenance(self) -> list[str]:
        """The commands that made the dataset (and its rotated source) and the runs."""
        return [*augmented_commands(self.data)] + [
            train_command(kind, run, self.data) for kind, run in self.runs.items()
        ]


def augmented_commands(folder: Path) -> list[str]:
    """``generate`` (of the source), ``dataset augment`` and ``dataset split`` of ``folder``;
    the plain :func:`dataset_commands` for a dataset that was not augmented."""
    try:
        manifest = json.loads((folder / "manifest.json").read_text())
    except (OSError, ValueError):
        return dataset_commands(folder)
    source = manifest.get("source") or {}
    if manifest.get("kind") != "transformed" or not source.get("path"):
        return dataset_commands(folder)
    lines = [line for line in dataset_commands(folder) if not line.startswith("scpformer gen")]
    generate = (f"scpformer generate {source.get('family')} --n {source.get('n')} "
                f"--seed {source.get('seed')} --out {source['path']}")  # fmt: skip
    angles = manifest.get("transform", {}).get("config", {}).get("angles_deg", [])
    augment = (
        f"scpformer dataset augment {source['path']} --out {folder}  # {len(angles)} rotations"
    )
    return [generate, augment, *lines]


def open_tscvx_study(options: RunOptions, kinds: Sequence[str] | None = None) -> TscvxStudy:
    """Check ``--data`` (a split ``pdg6dof`` dataset) and ``--model`` (one run per kind)."""
    from scpformer.data.storage import read_manifest

    data = require_data(options)
    manifest = read_manifest(data)
    if manifest.family != "pdg6dof":
        raise ValueError(f"--data {data}: a {manifest.family} dataset, not pdg6dof")
    runs: dict[str, Path] = {}
    for path in require_models(options):
        kind = predictor_kind(path)
        if kind in runs:
            raise ValueError(f"--model: two {kind} runs ({runs[kind]}, {path}); give one")
        runs[kind] = path
    wanted = kinds or ("tscvx",)
    missing = [k for k in wanted if k not in runs]
    if "tscvx" not in runs or (kinds and missing):
        raise ValueError(f"--model: this experiment needs runs of kind(s) {', '.join(wanted)}")
    return TscvxStudy(data, manifest.config, runs)


def train_command(kind: str, run: Path, data: Path) -> str:
    """The ``scpformer train`` line of a run, from its ``config.json`` or ``lookup.json``."""
    if kind == "tscvx":
        try:
            preset = json.loads((run / "config.json").read_text()).get("preset")
        except (OSError, ValueError):
            if (run / "MODEL_CARD.md").is_file():  # a shipped model: weights and card only
                return f"# {run}: the shipped model; its commands are in {run}/MODEL_CARD.md"
            return f"# {run}: no readable config.json (command unknown)"
        return f"scpformer train tscvx --data {data} --out {run} --preset {preset}"
    try:
        config = json.loads((run / "lookup.json").read_text())["config"]
    except (OSError, ValueError, KeyError):
        return f"# {run}: no readable lookup.json (command unknown)"
    points = config.get("max_points", 0)
    return (f"scpformer train {kind} --data {data} --out {run} --n-components "
            f"{config.get('n_components')} --max-points {points}")  # fmt: skip


def solver_config(config: dict[str, Any]) -> Any:
    """The dataset's :class:`~scpformer.data.pdg6dof_family.PDG6DoFDataConfig`."""
    from scpformer.data.pdg6dof_family import PDG6DoFDataConfig

    return PDG6DoFDataConfig.from_dict(config)


# ======================================================================================
# per-instance work: cold SCvx and T-SCvx with each predictor
# ======================================================================================
class SolveTimeSolver:
    """Cold SCvx and T-SCvx with every predictor of ``runs`` on one instance (a TaskSolver)."""

    def __init__(self, runs: dict[str, Path], data_config: dict[str, Any]) -> None:
        self.runs, self.data_config = dict(runs), data_config
        self.predictors: dict[str, Any] = {}

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "predictors": {}}

    def warm_up(self) -> None:
        import torch

        from scpformer.data.pdg6dof_family import PDG6DoFFamily
        from scpformer.models.predictors import load_predictor

        torch.set_num_threads(1)
        self.predictors = {kind: load_predictor(run, kind) for kind, run in self.runs.items()}
        for predictor in self.predictors.values():  # traces the T-SCvx networks
            predictor.warm_up()
        PDG6DoFFamily(solver_config(self.data_config)).warm_up()

    def methods(self, index: int) -> list[str]:
        """Cold SCvx and the predictors, reversed on odd instances."""
        order = [COLD, *self.predictors]
        return order if index % 2 == 0 else order[::-1]

    def solve(self, task: InstanceTask) -> dict[str, Any]:
        instance, done = self.solutions(task)
        row: dict[str, Any] = {KEY: task.index, "status": "ok", "message": ""}
        for method, (solution, wall) in done.items():
            row.update(method_columns(method, solution, wall, instance, done[COLD][0]))
        return row

    def solutions(self, task: InstanceTask) -> tuple[Any, dict[str, tuple[Any, float]]]:
        """The instance of ``task`` and, per method in :meth:`methods` order, its solution and
        wall time (inference included)."""
        from scpformer.data.pdg6dof_family import instance_from_theta

        config = solver_config(self.data_config)
        instance = instance_from_theta(task.theta, config.constants)
        done = {
            method: self._timed(method, instance, config.solver)
            for method in self.methods(task.index)
        }
        return instance, done

    def _timed(self, method: str, instance: Any, solver: Any) -> tuple[Any, float]:
        from scpformer.pdg6dof import solve
        from scpformer.warmstart.tscvx import TscvxWarmStart

        if method == COLD:
            start = time.perf_counter()
            solution = solve(instance, solver, method="scvx")
        else:
            warmstart = TscvxWarmStart(self.predictors[method])
            start = time.perf_counter()
            solution = solve(instance, solver, method="tscvx", warmstart=warmstart)
        return solution, time.perf_counter() - start


def method_columns(method: str, solution: Any, wall: float, instance: Any, cold: Any) -> dict:
    """The ``{method}_*`` cells of one solve (gap: extra propellant over cold SCvx's)."""
    from scpformer.problems.pdg6dof.problem import propellant_gap

    log = solution.extras.get("tscvx") or {}
    record = solution.extras.get("warmstart") or {}
    both = solution.converged and cold.converged
    cells = {
        "status": solution.status.value,
        "time_s": wall,
        "iterations": solution.iterations,
        "cost": solution.cost,
        "verified": bool(solution.verification and solution.verification.passed),
        "gap": propellant_gap(instance, solution.cost, cold.cost) if both else math.nan,
        "fallback": log.get("fallback") or "",
        "rows_kept": float(np.mean(log["rows_kept"])) if log.get("rows_kept") else math.nan,
        "guess_accepted": record.get("accepted", ""),
    }
    return {f"{method}_{name}": value for name, value in cells.items()}


def columns_for(methods: Sequence[str], extra: Sequence[str] = ()) -> tuple[str, ...]:
    """The results table of a solve study over ``methods``."""
    cells = tuple(f"{m}_{name}" for m in methods for name in PER_METHOD)
    return result_columns(*extra, *cells)


def solve_rows(
    study: TscvxStudy,
    options: RunOptions,
    positions: np.ndarray,
    extra: dict[int, dict[str, Any]] | None = None,
) -> list[dict[str, str]]:
    """Run (or resume) the solve study on ``positions`` (the settings checked by
    :func:`start_report`); ``extra`` adds cells per position."""
    methods = [COLD, *study.runs]
    extra_names = sorted({k for cells in (extra or {}).values() for k in cells})
    results = ResultsCSV(options.out / RESULTS_NAME, columns_for(methods, extra_names))
    solver = _ExtraCells(SolveTimeSolver(study.runs, study.config), extra or {})
    return run_tasks(solver, theta_tasks(study.data, positions), options, results)


class _ExtraCells:
    """A TaskSolver that adds fixed cells (e.g. the OOD flag) to another's rows."""

    def __init__(self, inner: SolveTimeSolver, cells: dict[int, dict[str, Any]]) -> None:
        self.inner, self.cells = inner, cells

    def warm_up(self) -> None:
        self.inner.warm_up()

    def solve(self, task: InstanceTask) -> dict[str, Any]:
        return {**self.inner.solve(task), **self.cells.get(int(task.index), {})}


# ======================================================================================
# analysis of a solve study
# ======================================================================================
#: Propellant difference below which two solves tie [U_M]: SCvx's stationarity test,
#: ``eps_opt max(1, |J|)`` (eps_opt = 1e-4, |J| = m_f <= m0 = 3 U_M).
TIE_PROPELLANT = 3e-4


def method_stats(rows: Sequence[dict[str, str]], method: str) -> dict[str, float]:
    """Converged rate, solve-time statistics, iterations, gaps and fallbacks of ``method``."""
    times = column(rows, f"{method}_time_s")
    gaps = column(rows, f"{method}_gap")
    gaps = gaps[np.isfinite(gaps)]
    converged = np.array([r.get(f"{method}_status") == "converged" for r in rows])
    fallbacks = sum(bool(r.get(f"{method}_fallback")) for r in rows)
    return {
        "n": len(rows),
        "converged": float(converged.mean()) if len(rows) else math.nan,
        "mean_s": float(np.mean(times)) if len(rows) else math.nan,
        "median_s": float(np.median(times)) if len(rows) else math.nan,
        "std_s": float(np.std(times)) if len(rows) else math.nan,
        "iterations": float(np.median(column(rows, f"{method}_iterations"))) if rows else math.nan,
        "gap_median": float(np.median(gaps)) if gaps.size else math.nan,
        "gap_max": float(np.max(gaps)) if gaps.size else math.nan,
        "fallbacks": float(fallbacks),
    }


def stats_table(rows: Sequence[dict[str, str]], methods: Sequence[str]) -> str:
    """Markdown table of :func:`method_stats` per method, speed-ups against cold SCvx."""
    cold = method_stats(rows, COLD)
    lines = []
    for m in methods:
        s = method_stats(rows, m)
        lines.append(
            (
                m,
                s["n"],
                f"{s['converged']:.1%}",
                rep.fmt(s["mean_s"]),
                rep.fmt(s["median_s"]),
                rep.fmt(s["std_s"]),
                rep.fmt(cold["mean_s"] / s["mean_s"]),
                rep.fmt(cold["median_s"] / s["median_s"]),
                rep.fmt(s["iterations"]),
                pct(s["gap_median"]),
                pct(s["gap_max"]),
                int(s["fallbacks"]),
            )
        )
    header = (
        "method",
        "instances",
        "converged",
        "mean s",
        "median s",
        "std s",
        "mean speed-up",
        "median speed-up",
        "median solves",
        "median gap",
        "max gap",
        "fallbacks",
    )
    return rep.markdown_table(header, lines)


def outcomes(rows: Sequence[dict[str, str]], method: str) -> Outcomes:
    """``method``'s whole-path wall time, conic solves, solved flag (converged and verified)
    and cost per row."""
    solved = [
        r.get(f"{method}_status") == "converged" and r.get(f"{method}_verified", "True") == "True"
        for r in rows
    ]
    return Outcomes(
        time=column(rows, f"{method}_time_s"),
        iterations=column(rows, f"{method}_iterations"),
        solved=np.array(solved, dtype=bool),
        cost=column(rows, f"{method}_cost"),
    )


def paired_section(rows: Sequence[dict[str, str]], methods: Sequence[str]) -> str:
    """Each method against cold SCvx instance by instance (:mod:`..paired`); a propellant
    difference within SCvx's stationarity tolerance (3e-4 U_M) ties."""
    base = outcomes(rows, COLD)
    tables = [f"**{m} against cold SCvx**\n\n" + paired_table(m, outcomes(rows, m), COLD, base,
                                                            cost_tie=TIE_PROPELLANT)
              for m in methods if m != COLD]  # fmt: skip
    return "\n\n".join(tables) or "No method to compare with cold SCvx."


def pct(value: float) -> str:
    """``value`` as a percentage with three significant digits, ``n/a`` when not finite."""
    return "n/a" if not math.isfinite(value) else f"{100 * value:.3g}%"


def comparison_rows(rows: Iterable[ComparisonRow]) -> list[rep.Comparison]:
    """The paper-vs-ours rows of a report from a table of ``(quantity, paper, ours[, note])``.

    Parameters
    ----------
    rows
        One tuple per row: the quantity, the paper's number as printed, ours, and optionally
        a note.

    Returns
    -------
    list of Comparison
        The rows, in order.
    """
    return [
        rep.Comparison(quantity=quantity, paper=paper, ours=ours, note=note[0] if note else "")
        for quantity, paper, ours, *note in rows
    ]


def start_report(
    options: RunOptions, study: TscvxStudy, name: str, command: str, reproduces: str, **extra: Any
) -> rep.Report:
    """Record this run's settings in ``--out`` (refusing a folder made with other settings) and
    start its report, with the T-SCvx differences.

    Parameters
    ----------
    options, study
        The experiment's options and its checked dataset and runs.
    name, command
        The experiment's name and the command line that ran it.
    reproduces
        What of the T-SCvx paper it reproduces (e.g. ``"Fig. 2"``).
    **extra
        Further settings (:func:`study_settings`), e.g. ``n``.

    Returns
    -------
    Report
        The report, its settings those recorded in ``--out``.
    """
    settings = study_settings(options, study, name, **extra)
    check_settings(options.out, settings)
    return rep.Report(name, f"{PAPER} {reproduces}", command, settings, study.provenance(),
                      differences=TSCVX_DIFFERENCES)  # fmt: skip


def study_settings(options: RunOptions, study: TscvxStudy, name: str, **extra: Any) -> dict:
    """The settings of experiment ``name`` on ``study``: the options, the dataset's solver, the
    runs and the SHA-256 of their weight and table files, and ``extra``."""
    from scpformer.data.storage import file_sha256

    digests = {}
    for kind, run in study.runs.items():
        files = sorted(p for p in run.rglob("*") if p.suffix in (".pt", ".npz"))
        digests[kind] = {str(p.relative_to(run)): file_sha256(p) for p in files}
    return settings_dict(
        options,
        experiment=name,
        solver=study.config.get("solver"),
        runs={k: str(v) for k, v in study.runs.items()},
        run_files_sha256=digests,
        **extra,
    )
