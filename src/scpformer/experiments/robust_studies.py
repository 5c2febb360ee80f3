"""The robust ART paper's experiments (Sec. 5): ``robust-warmstart`` (Figs. 5-6).

``robust-warmstart``: on test-split instances of a ``robust-rendezvous`` dataset (rebuilt from
theta with the dataset's scenario, uncertainty model and solver), for both passive-safety
modes -- deterministic (``X = 0``, "-D") and chance-constrained ("-C") -- SCvx* runs from

* CVX, the convex TPBVP (PS-CVX-D / PS-CVX-C), and
* ART (PS-ART-D / PS-ART-C) for every given model (trained on RTN or on ROE states; the frame
  is read from the checkpoint), conditioned on ``R(t_1) = -J_CVX``, ``C(t_1) = 0``, with the
  paper's post hoc acceptance check (Eq. 8; a rejected guess falls back to CVX).

Per instance, mode and warm start it records the SCvx* cost, status, iterations, warm-start
and SCP time, and ART's acceptance decision with ``E_R`` and ``E_C``. The analysis follows
Figs. 5-6: averages over the instances with ``C_CVX(t_1) >= x`` (the paper's x-axis, with
the mode's own Eq. 7 budget), the suboptimality ``J_SCP - J_CVX``, the improvement ratio
``(J_SCP,CVX - J_SCP,ART) / (J_SCP,CVX - J_CVX)`` (of the bin means), SCP iterations, runtime,
the infeasibility rate (runs that do not converge: infeasible or at max_iterations) and the
histogram of ``J_SCP,CVX - J_SCP,ART``.

``robust-trajectory`` (Figs. 7-8) and ``robust-posthoc`` (Figs. 9-10) run the same solves in
the chance-constrained mode (the latter without the acceptance check, recording what it would
decide); their analyses are in :mod:`scpformer.experiments.robust_posthoc`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.runner import (
    KEY,
    RESULTS_NAME,
    InstanceTask,
    ModelSolver,
    ResultsCSV,
    RunOptions,
    check_settings,
    column,
    open_study,
    require_n,
    run_tasks,
    select_test_instances,
    settings_dict,
    theta_tasks,
)
from scpformer.experiments.warmstart_study import mean_over, plot_counts

NAME = "robust-warmstart"
MODES = {"deterministic": "D", "chance": "C"}
THRESHOLDS = (0, 1, 2, 5, 10, 15, 20)  # C_CVX(t_1) >= x
PER_SOURCE = (
    "status",
    "cost",
    "iterations",
    "ws_time",
    "scp_time",
    "converged",
    "accepted",
    "E_R",
    "E_C",
    "would_accept",
)
FAMILY = "robust-rendezvous"


def sources(frames: tuple[str, ...]) -> tuple[str, ...]:
    """Warm starts of the study: ``cvx`` and ``art_<frame>`` per model."""
    return ("cvx", *(f"art_{f}" for f in frames))


def columns(frames: tuple[str, ...], modes: tuple[str, ...] = tuple(MODES)) -> tuple[str, ...]:
    per = [f"{m}_{s}_{name}" for m in modes for s in sources(frames) for name in PER_SOURCE]
    budgets = [f"{m}_c_cvx_t1" for m in modes]
    return (KEY, "j_cvx", *budgets, *per, "status", "message")


def label(mode: str, source: str) -> str:
    """The paper's name: PS-CVX-C, PS-ART-D (RTN), ..."""
    kind = "CVX" if source == "cvx" else "ART"
    frame = "" if source == "cvx" else f" ({source.split('_')[1].upper()})"
    return f"PS-{kind}-{MODES[mode]}{frame}"


class RobustWarmstartSolver(ModelSolver):
    """Per-instance SCvx* from CVX and from ART in ``modes`` (runs in the executor's workers).

    ``check`` applies the post hoc acceptance check (Eq. 8, CVX fallback); without it ART's
    own guess always starts SCvx* and ``would_accept`` records what the check would decide.
    """

    family = FAMILY

    def __init__(
        self,
        checkpoints: tuple[Path, ...],
        data_config: dict[str, Any],
        modes: tuple[str, ...] = tuple(MODES),
        check: bool = True,
    ) -> None:
        super().__init__(checkpoints, data_config)
        self.modes, self.check = modes, check

    def warm_up(self) -> None:
        from scpformer.data.family import build_family

        super().warm_up()
        build_family(FAMILY, self.data_config).warm_up()

    def instance(self, theta: np.ndarray) -> Any:
        from scpformer.data.robust_rendezvous_family import RobustDataConfig, instance_from_theta

        config = RobustDataConfig.from_dict(self.data_config)
        return instance_from_theta(theta, config.scenario, config.uncertainty)

    def guesses(self, instance: Any, mode: str) -> dict[str, Any]:
        """CVX's and every model's warm start (``WarmStartResult``) in ``mode``."""
        from scpformer.data.robust_rendezvous_family import RobustDataConfig
        from scpformer.warmstart import ArtWarmStart, PrecomputedWarmStart, RobustTpbvpWarmStart

        solver = RobustDataConfig.from_dict(self.data_config).solver
        cvx = RobustTpbvpWarmStart(solver, mode).guess(instance)
        out = {"cvx": cvx}
        for ckpt in self.models:
            art = ArtWarmStart(
                ckpt.model,
                ckpt.normalization,
                frame=ckpt.frame,
                family=FAMILY,
                mode=mode,
                config=solver,
                fallback=PrecomputedWarmStart(cvx),
                acceptance="family" if self.check else None,
            )
            out[f"art_{ckpt.frame}"] = art.guess(instance)
        return out

    def scp(self, instance: Any, mode: str, guess: Any) -> Any:
        """SCvx* from ``guess`` (no final verification)."""
        from scpformer.data.robust_rendezvous_family import RobustDataConfig
        from scpformer.problems.robust_rendezvous.problem import solve
        from scpformer.warmstart import PrecomputedWarmStart

        solver = RobustDataConfig.from_dict(self.data_config).solver
        return solve(instance, solver, mode, warmstart=PrecomputedWarmStart(guess), verify=False)

    def solve(self, task: InstanceTask) -> dict[str, Any]:
        instance = self.instance(task.theta)
        row: dict[str, Any] = {KEY: task.index, "status": "ok", "message": ""}
        for mode in self.modes:
            guesses = self.guesses(instance, mode)
            row["j_cvx"] = guesses["cvx"].record.cost
            row[f"{mode}_c_cvx_t1"] = guesses["cvx"].record.constraint_to_go
            for source, guess in guesses.items():
                row.update(self._fields(instance, mode, f"{mode}_{source}", guess))
        return row

    def _fields(self, instance: Any, mode: str, prefix: str, guess: Any) -> dict[str, Any]:
        from scpformer.warmstart import AcceptanceCheck

        record, details = guess.record, guess.record.details
        out: dict[str, Any] = {
            f"{prefix}_ws_time": record.time_s,
            f"{prefix}_accepted": record.accepted,
        }
        if "art_cost" in details:  # an ART guess: what the Eq. 8 check says about it
            decision = AcceptanceCheck().evaluate(
                rtg_desired=details["rtg0"],
                ctg_desired=details["ctg0"],
                rtg_realized=-details["art_cost"],
                ctg_realized=details["art_constraint_to_go"],
            )
            out.update(
                {
                    f"{prefix}_E_R": decision.E_R,
                    f"{prefix}_E_C": decision.E_C,
                    f"{prefix}_would_accept": decision.accepted,
                }
            )
        if guess.trajectory is None:
            return {**out, f"{prefix}_status": "no_warm_start", f"{prefix}_converged": False}
        solution = self.scp(instance, mode, guess)
        return {
            **out,
            f"{prefix}_status": solution.status.value,
            f"{prefix}_cost": solution.cost,
            f"{prefix}_iterations": solution.iterations,
            f"{prefix}_scp_time": solution.timing.total if solution.timing else math.nan,
            f"{prefix}_converged": solution.converged,
        }


# what each robust experiment runs: passive-safety modes, acceptance check, paper figures
STUDIES = {
    "robust-warmstart": (tuple(MODES), True, "robust ART paper Figs. 5-6"),
    "robust-trajectory": (("chance",), True, "robust ART paper Figs. 7-8"),
    "robust-posthoc": (("chance",), False, "robust ART paper Figs. 9-10"),
}


def run(options: RunOptions, *, command: str = "", name: str = NAME) -> Path:
    """Run ``robust-warmstart``, ``robust-trajectory`` or ``robust-posthoc``."""
    if name not in STUDIES:
        raise ValueError(f"name must be one of {tuple(STUDIES)}, got {name!r}")
    modes, check, reproduces = STUDIES[name]
    study = open_study(options, FAMILY)
    frames = tuple(c.frame for c in study.checkpoints)
    if len(set(frames)) != len(frames):
        raise ValueError(f"--model: one run per state frame (rtn, roe), got {frames}")
    positions = select_test_instances(study.data, require_n(options), options.seed)
    settings = settings_dict(
        options,
        study,
        experiment=name,
        n=int(positions.size),
        frames=frames,
        modes=modes,
        conditioning="R(t_1) = -J_CVX, C(t_1) = 0, Algorithm 2, "
        + ("post hoc check (Eq. 8) with CVX fallback" if check else "no acceptance check"),
    )
    check_settings(options.out, settings)
    tasks = theta_tasks(study.data, positions)
    results = ResultsCSV(options.out / RESULTS_NAME, columns(frames, modes))
    solver = RobustWarmstartSolver(study.models, study.manifest.config, modes, check)
    rows = run_tasks(solver, tasks, options, results)
    report = rep.Report(
        name=name,
        reproduces=reproduces,
        command=command,
        settings=settings,
        provenance=study.provenance(),
        differences=ROBUST_DIFFERENCES,
    )
    report.sections.append(("Instances", f"{len(rows)} of {positions.size} test instances."))
    if rows and name == "robust-warmstart":
        analyse(rows, frames, report, options.out)
    elif rows and name == "robust-posthoc":
        from scpformer.experiments.robust_posthoc import analyse_posthoc

        analyse_posthoc(rows, frames[0], report, options.out)
    elif rows:
        from scpformer.experiments.robust_posthoc import show_trajectory

        show_trajectory(rows, frames[0], solver, tasks, report, options.out)
    return report.write(options.out)


ROBUST_DIFFERENCES = (
    "Conic solver: the dataset's solver through cvxpy (Clarabel by default).",
    "Dataset and model sizes: the paper's datasets and its six-layer, six-head GPT are far "
    "larger than ours (the dataset and preset are named in the commands above).",
    "Splits are grouped by base instance (twins never straddle train and test).",
    "SCvx* runs here without the final verification (`verify=False`): converged means "
    "SCvx*'s own stopping test, as in the paper's infeasibility rate.",
)


def bin_stats(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...], mask: np.ndarray
) -> dict[str, float]:
    """Figs. 5-6 metrics of ``mode`` over the instances in ``mask``."""
    j_cvx = column(rows, "j_cvx")
    conv = {s: column(rows, f"{mode}_{s}_converged") == 1.0 for s in sources(frames)}
    cost = {s: column(rows, f"{mode}_{s}_cost") for s in sources(frames)}
    out: dict[str, float] = {"count": int(mask.sum())}
    for s in sources(frames):
        both = mask & conv[s] & conv["cvx"]
        out[f"{s}_gap"] = mean_over(cost[s] - j_cvx, both)
        out[f"{s}_cvx_gap"] = mean_over(cost["cvx"] - j_cvx, both)
        out[f"{s}_iterations"] = mean_over(column(rows, f"{mode}_{s}_iterations"), mask & conv[s])
        out[f"{s}_time"] = mean_over(
            column(rows, f"{mode}_{s}_ws_time") + column(rows, f"{mode}_{s}_scp_time"), mask
        )
        out[f"{s}_infeasible_pct"] = 100.0 * mean_over(~conv[s], mask)
        out[f"{s}_accepted_pct"] = 100.0 * mean_over(column(rows, f"{mode}_{s}_accepted"), mask)
        gap = out[f"{s}_cvx_gap"]
        out[f"{s}_improvement"] = 100.0 * (gap - out[f"{s}_gap"]) / gap if gap > 0 else math.nan
    return out


def analyse(
    rows: list[dict[str, str]], frames: tuple[str, ...], report: rep.Report, out: Path
) -> None:
    """Per mode: the table by threshold, the figure, and the paper's claims."""
    C = rep.Comparison
    for mode, letter in MODES.items():
        c = column(rows, f"{mode}_c_cvx_t1")
        stats = [{"x": x, **bin_stats(rows, mode, frames, c >= x)} for x in THRESHOLDS]
        header = [
            "C_CVX >=",
            "n",
            *(
                f"{label(mode, s)} {what}"
                for s in sources(frames)
                for what in ("gap [m/s]", "impr. [%]", "iter.", "time [s]", "infeas. [%]")
            ),
        ]
        table = [
            [
                s["x"],
                s["count"],
                *(
                    v
                    for src in sources(frames)
                    for v in (
                        rep.fmt(s[f"{src}_gap"]),
                        rep.fmt(s[f"{src}_improvement"]),
                        rep.fmt(s[f"{src}_iterations"]),
                        rep.fmt(s[f"{src}_time"], 2),
                        rep.fmt(s[f"{src}_infeasible_pct"]),
                    )
                ),
            ]
            for s in stats
        ]
        report.sections.append(
            (
                f"{'Fig. 5' if letter == 'D' else 'Fig. 6'}: {mode} passive "
                "safety, by C_CVX(t_1) >= x",
                rep.markdown_table(header, table),
            )
        )
        every = stats[0]
        paper_impr = "up to 35" if letter == "D" else "up to 22"
        for s in sources(frames)[1:]:
            best = max(
                (st[f"{s}_improvement"] for st in stats if math.isfinite(st[f"{s}_improvement"])),
                default=math.nan,
            )
            report.comparisons += [
                C(
                    quantity=f"{label(mode, s)}: largest improvement ratio over the C_CVX bins [%]",
                    paper=paper_impr,
                    ours=rep.fmt(best),
                ),
                C(
                    quantity=f"{label(mode, s)} vs PS-CVX-{letter}: SCP iterations (all)",
                    paper="fewer with ART",
                    ours=f"{rep.fmt(every[f'{s}_iterations'])} vs "
                    f"{rep.fmt(every['cvx_iterations'])}",
                ),
                C(
                    quantity=f"{label(mode, s)} vs PS-CVX-{letter}: infeasibility rate (all) [%]",
                    paper="lower with ART"
                    + (" (CVX high in the chance case)" if letter == "C" else ""),
                    ours=f"{rep.fmt(every[f'{s}_infeasible_pct'])} vs "
                    f"{rep.fmt(every['cvx_infeasible_pct'])}",
                    note=f"ART guesses accepted: {rep.fmt(every[f'{s}_accepted_pct'])}%",
                ),
            ]
        report.figures.append(_figure(rows, mode, frames, stats, out))


def _figure(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...], stats: list[dict], out: Path
) -> tuple[str, str]:
    x = np.array([s["x"] for s in stats], dtype=float)
    fig, axes = rep.new_figure(ncols=4, width=16.0)
    colors = dict(zip(sources(frames), ("tab:blue", "tab:red", "tab:orange"), strict=False))
    for ax, key, ylabel in zip(
        axes[:3],
        ("gap", "iterations", "infeasible_pct"),
        ("J_SCP - J_CVX [m/s]", "SCP iterations", "infeasibility rate [%]"),
        strict=True,
    ):
        for s in sources(frames):
            ax.plot(
                x, [st[f"{s}_{key}"] for st in stats], "o-", color=colors[s], label=label(mode, s)
            )
        ax.set_xlabel("C_CVX(t_1) >= x")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=7)
        plot_counts(ax, x, stats)
    cvx = column(rows, f"{mode}_cvx_cost")
    cvx_ok = column(rows, f"{mode}_cvx_converged") == 1.0
    for s in sources(frames)[1:]:
        diff = cvx - column(rows, f"{mode}_{s}_cost")
        diff = diff[cvx_ok & (column(rows, f"{mode}_{s}_converged") == 1.0)]
        if diff.size:
            axes[3].hist(diff, bins=20, alpha=0.6, color=colors[s], label=label(mode, s))
            for v in (diff.min(), diff.max()):
                axes[3].axvline(v, color="red", ls=":")
    axes[3].set_xlabel("J_SCP,CVX - J_SCP,ART [m/s]")
    axes[3].set_ylabel("instances")
    axes[3].legend(fontsize=7)
    number = "5" if mode == "deterministic" else "6"
    file = rep.save_figure(fig, out / f"fig{number}_{mode}.png")
    return file, f"Fig. {number}: {mode} passive safety, SCvx* from CVX and ART"
