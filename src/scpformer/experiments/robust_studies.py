"""The robust ART paper's experiments (Sec. 5): ``robust-warmstart`` (Figs. 5-6).

``robust-warmstart``: on test-split instances of a ``robust-rendezvous`` dataset (rebuilt from
theta with the dataset's scenario, uncertainty model and solver), for both passive-safety
modes -- deterministic (``X = 0``, "-D") and chance-constrained ("-C") -- SCvx* runs from

* CVX, the convex TPBVP (PS-CVX-D / PS-CVX-C), and
* ART (PS-ART-D / PS-ART-C) for every given model (trained on RTN or on ROE states; the frame
  is read from the checkpoint), conditioned on ``R(t_1) = -J_CVX``, ``C(t_1) = 0``, without
  the post hoc acceptance check, as in the paper's Figs. 5-6 (Sec. 5 adds the check only
  afterwards, Fig. 10); each row records what the check (Eq. 8) would decide, and the report
  also gives the numbers with it (:func:`with_check`: a rejected guess falls back to CVX).

Per instance, mode and warm start it records the SCvx* cost, status, iterations, warm-start
and SCP time, and ART's acceptance decision with ``E_R`` and ``E_C``; ``J_CVX`` and the
``C_CVX(t_1)`` bins come from the TPBVP solved to tight tolerances
(:func:`~scpformer.problems.robust_rendezvous.tpbvp.tpbvp_lower_bound`), not from the CVX
warm start's default solve, whose cost lies up to 2.5e-4 above it. The analysis follows
Figs. 5-6 (six panels): averages over the instances with ``C_CVX(t_1) >= x`` (the paper's
x-axis, with the mode's own Eq. 7 budget) of the suboptimality ``J_SCP - J_CVX``, the
improvement ratio ``(J_SCP,CVX - J_SCP,ART) / (J_SCP,CVX - J_CVX)`` (of the bin means), SCP
iterations, runtime (warm start + SCP), the infeasibility rate (runs that do not converge:
infeasible or at max_iterations; the report splits it by status) and the histogram of
``J_SCP,CVX - J_SCP,ART``.

``robust-trajectory`` (Figs. 7-8) and ``robust-posthoc`` (Figs. 9-10) run the same solves in
the chance-constrained mode; their analyses are in :mod:`scpformer.experiments.robust_posthoc`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.paired import Outcomes, exact_sign_test, paired_table
from scpformer.experiments.runner import (
    KEY,
    InstanceTask,
    ModelSolver,
    RunOptions,
    column,
    open_study,
    result_columns,
    select_and_record,
    solve_tasks,
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
DISCUSSION_NAME = "discussion.md"  # written by hand after a run; included in report.md


def sources(frames: tuple[str, ...]) -> tuple[str, ...]:
    """Warm starts of the study: ``cvx`` and ``art_<frame>`` per model."""
    return ("cvx", *(f"art_{f}" for f in frames))


def columns(frames: tuple[str, ...], modes: tuple[str, ...] = tuple(MODES)) -> tuple[str, ...]:
    per = [f"{m}_{s}_{name}" for m in modes for s in sources(frames) for name in PER_SOURCE]
    budgets = [f"{m}_c_cvx_t1" for m in modes]
    return result_columns("j_cvx", *budgets, *per)


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
        from dataclasses import replace

        from scpformer.data.robust_rendezvous_family import RobustDataConfig
        from scpformer.robust_rendezvous import solve
        from scpformer.warmstart import PrecomputedWarmStart

        solver = replace(RobustDataConfig.from_dict(self.data_config).solver, safety_mode=mode)
        warmstart = PrecomputedWarmStart(guess)
        return solve(instance, solver, method="passive_safety", warmstart=warmstart, verify=False)

    def solve(self, task: InstanceTask) -> dict[str, Any]:
        instance = self.instance(task.theta)
        from scpformer.data.robust_rendezvous_family import RobustDataConfig
        from scpformer.problems.robust_rendezvous.tpbvp import tpbvp_lower_bound
        from scpformer.problems.robust_rendezvous.warmstart import initial_budget

        bound = tpbvp_lower_bound(instance, RobustDataConfig.from_dict(self.data_config).solver)
        row: dict[str, Any] = {KEY: task.index, "status": "ok", "message": "", "j_cvx": bound.cost}
        for mode in self.modes:
            guesses = self.guesses(instance, mode)
            row[f"{mode}_c_cvx_t1"] = initial_budget(instance, bound, mode)
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
            f"{prefix}_iterations": scvx_star_iterations(solution),
            f"{prefix}_scp_time": solution.timing.total if solution.timing else math.nan,
            f"{prefix}_converged": solution.converged,
        }


def scvx_star_iterations(solution: Any) -> int:
    """SCvx* solves of the passive-safety stage, also when it failed (the solution's own count
    when no such stage ran): ``solution.iterations``, which the robust ``solve`` pairs with the
    passive-safety stage's status (``problem._assemble``)."""
    return int(solution.iterations)


# what each robust experiment runs: passive-safety modes, acceptance check, paper figures
STUDIES = {
    # Figs. 5-8 are without the check (Sec. 5 re-evaluates Fig. 6a with it in Fig. 10); the
    # checked numbers follow from the rows (a rejected guess repeats the CVX-started run)
    "robust-warmstart": (tuple(MODES), False, "robust ART paper Figs. 5-6"),
    "robust-trajectory": (("chance",), False, "robust ART paper Figs. 7-8"),
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
    acceptance = ("post hoc check (Eq. 8) with CVX fallback" if check
                  else "no acceptance check (its decision is recorded)")  # fmt: skip
    positions, settings = select_and_record(
        options, study, experiment=name, frames=frames, modes=modes,
        conditioning=f"R(t_1) = -J_CVX, C(t_1) = 0, Algorithm 2, {acceptance}",
    )  # fmt: skip
    tasks = theta_tasks(study.data, positions)
    solver = RobustWarmstartSolver(study.models, study.manifest.config, modes, check)
    rows = solve_tasks(solver, tasks, options, columns(frames, modes))
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
        analyse(rows, frames, report, options.out, study.checkpoints)
    elif rows and name == "robust-posthoc":
        from scpformer.experiments.robust_posthoc import analyse_posthoc

        analyse_posthoc(rows, frames, report, options.out)
    elif rows:
        from scpformer.experiments.robust_posthoc import show_trajectory

        show_trajectory(rows, frames, solver, tasks, report, options.out)
    notes = discussion(options.out)
    if notes:
        report.sections.append(notes)
    return report.write(options.out)


ROBUST_DIFFERENCES = (
    "Conic solver: the dataset's solver through cvxpy (Clarabel by default).",
    "Dataset and model sizes: the paper's datasets and its six-layer, six-head GPT are far "
    "larger than ours (the dataset and preset are named in the commands above).",
    "Splits are grouped by base instance (twins never straddle train and test) and hold a "
    "validation share (0.8/0.1/0.1); the paper splits 90/10 train/test.",
    "SCvx* runs here without the final verification (`verify=False`): converged means "
    "SCvx*'s own stopping test, as in the paper's infeasibility rate.",
)


def bin_stats(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...], mask: np.ndarray
) -> dict[str, float]:
    """Figs. 5-6 metrics of ``mode`` over the instances in ``mask``.

    Suboptimality ``J_SCP - J_CVX`` and the improvement ratio
    ``(J_SCP,CVX - J_SCP,ART) / (J_SCP,CVX - J_CVX)`` over the instances where both SCvx*
    runs converged; iterations over the converged runs; runtime (warm start + SCvx*) and the
    infeasibility rate (infeasible or not converged) over every instance in ``mask``.
    """
    j_cvx = column(rows, "j_cvx")
    conv = {s: column(rows, f"{mode}_{s}_converged") == 1.0 for s in sources(frames)}
    cost = {s: column(rows, f"{mode}_{s}_cost") for s in sources(frames)}
    out: dict[str, float] = {"count": int(mask.sum())}
    for s in sources(frames):
        both = mask & conv[s] & conv["cvx"]
        ws_time = column(rows, f"{mode}_{s}_ws_time")
        scp_time = np.nan_to_num(column(rows, f"{mode}_{s}_scp_time"))  # no guess: no SCvx*
        out[f"{s}_gap"] = mean_over(cost[s] - j_cvx, both)
        out[f"{s}_cvx_gap"] = mean_over(cost["cvx"] - j_cvx, both)
        out[f"{s}_iterations"] = mean_over(column(rows, f"{mode}_{s}_iterations"), mask & conv[s])
        out[f"{s}_ws_time"] = mean_over(ws_time, mask)
        out[f"{s}_time"] = mean_over(ws_time + scp_time, mask)
        out[f"{s}_infeasible_pct"] = 100.0 * mean_over(~conv[s], mask)
        out[f"{s}_accepted_pct"] = 100.0 * mean_over(column(rows, f"{mode}_{s}_accepted"), mask)
        gap = out[f"{s}_cvx_gap"]
        out[f"{s}_improvement"] = 100.0 * (gap - out[f"{s}_gap"]) / gap if gap > 0 else math.nan
    return out


ART_FIELDS = ("status", "cost", "iterations", "scp_time", "converged")  # set by the SCvx* run


def with_check(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...]
) -> list[dict[str, str]]:
    """The rows as the post hoc check (Eq. 8) would make them: where it rejects ART's guess,
    SCvx* starts from CVX, so the ART run's outcome is the CVX run's (its warm-start time
    stays: ART was generated and checked before falling back)."""
    out = []
    for row in rows:
        row = dict(row)
        for s in sources(frames)[1:]:
            accept = row.get(f"{mode}_{s}_would_accept", "")
            if accept == "False":
                for name in ART_FIELDS:
                    row[f"{mode}_{s}_{name}"] = row.get(f"{mode}_cvx_{name}", "")
            row[f"{mode}_{s}_accepted"] = accept
        out.append(row)
    return out


def cost_differences(rows: list[dict[str, str]], mode: str, source: str) -> np.ndarray:
    """``J_SCP,CVX - J_SCP,ART`` [m/s] where both SCvx* runs converged (> 0: ART better)."""
    ok = (column(rows, f"{mode}_cvx_converged") == 1.0) & (
        column(rows, f"{mode}_{source}_converged") == 1.0
    )
    return (column(rows, f"{mode}_cvx_cost") - column(rows, f"{mode}_{source}_cost"))[ok]


def discordant_outcomes(
    rows: list[dict[str, str]], mode: str, source: str
) -> tuple[int, int, float]:
    """Instances whose SCvx* run converged only from ART, only from CVX, and the two-sided
    exact sign-test p-value of that split (:func:`~scpformer.experiments.paired.exact_sign_test`,
    McNemar's exact test: the two infeasibility rates compare the same instances, so they
    differ only through the discordant pairs).
    """
    art = column(rows, f"{mode}_{source}_converged") == 1.0
    cvx = column(rows, f"{mode}_cvx_converged") == 1.0
    only_art, only_cvx = int(np.sum(art & ~cvx)), int(np.sum(cvx & ~art))
    return only_art, only_cvx, exact_sign_test(only_art, only_cvx)


def _discordant_note(rows: list[dict[str, str]], mode: str, source: str) -> str:
    only_art, only_cvx, p = discordant_outcomes(rows, mode, source)
    return (
        f"converged only from ART / only from CVX: {only_art} / {only_cvx} (sign test p = {p:.2g})"
    )


def status_counts(rows: list[dict[str, str]], mode: str, source: str) -> dict[str, int]:
    """How the SCvx* runs from ``source`` ended: ``{status: count}``."""
    counts: dict[str, int] = {}
    for row in rows:
        status = row.get(f"{mode}_{source}_status", "") or "not run"
        counts[status] = counts.get(status, 0) + 1
    return counts


def analyse(
    rows: list[dict[str, str]],
    frames: tuple[str, ...],
    report: rep.Report,
    out: Path,
    checkpoints: tuple[Any, ...] = (),
) -> None:
    """Per mode: the table by threshold, the figure, the outcomes, and the paper's claims."""
    if checkpoints:
        report.sections.append(("Models", model_table(checkpoints)))
    report.sections.append(("Reading these numbers", room_for_improvement(rows)))
    for mode, letter in MODES.items():
        c = column(rows, f"{mode}_c_cvx_t1")
        checked = with_check(rows, mode, frames)
        stats = [{"x": x, **bin_stats(rows, mode, frames, c >= x)} for x in THRESHOLDS]
        stats_checked = [{"x": x, **bin_stats(checked, mode, frames, c >= x)} for x in THRESHOLDS]
        figure = "Fig. 5" if letter == "D" else "Fig. 6"
        report.sections += [
            (f"{figure}: {mode}, by C_CVX(t_1) >= x", _threshold_table(mode, frames, stats)),
            (
                f"{figure} with the post hoc check (Eq. 8, CVX fallback): {mode}",
                _threshold_table(mode, frames, stats_checked),
            ),
            (f"{figure}: how the SCvx* runs ended ({mode})", _outcome_table(rows, mode, frames)),
            (
                f"{figure} with the check: how the SCvx* runs ended ({mode})",
                _outcome_table(checked, mode, frames),
            ),
            (f"{figure}: ART's guesses and the check ({mode})", _check_table(rows, mode, frames)),
            (f"{figure}: instance by instance against PS-CVX-{letter} ({mode})",
             paired_text(rows, checked, mode, frames)),
        ]  # fmt: skip
        report.comparisons += _comparisons(rows, mode, frames, stats)
        report.comparisons += _checked_comparisons(mode, frames, stats, stats_checked, checked)
        report.figures.append(_figure(rows, mode, frames, stats, out))
    if len(frames) > 1:
        report.comparisons += _frame_comparisons(rows, frames)


def outcomes(rows: list[dict[str, str]], mode: str, source: str) -> Outcomes:
    """``source``'s whole path per instance in ``mode``: the warm start's time plus SCvx*'s
    (none without a guess), its iterations, converged or not, and its cost."""

    def col(name: str) -> np.ndarray:
        return column(rows, f"{mode}_{source}_{name}")

    return Outcomes(time=col("ws_time") + np.nan_to_num(col("scp_time")),
                    iterations=np.nan_to_num(col("iterations")), solved=col("converged") == 1.0,
                    cost=col("cost"))  # fmt: skip


def paired_text(
    rows: list[dict[str, str]], checked: list[dict[str, str]], mode: str,
    frames: tuple[str, ...],
) -> str:  # fmt: skip
    """Each ART start, without and with the post hoc check, against CVX draw by draw
    (:mod:`.paired`); a cost difference within SCvx*'s stopping tolerance (1e-6 m/s) ties."""
    base = outcomes(rows, mode, "cvx")
    cvx = label(mode, "cvx")
    tables = [
        f"**{name} against {cvx}**\n\n"
        + paired_table(name, outcomes(table, mode, source), cvx, base, cost_tie=1e-6)
        for source in sources(frames)[1:]
        for name, table in ((label(mode, source), rows),
                            (f"{label(mode, source)} with the check", checked))
    ]  # fmt: skip
    return "\n\n".join(tables) or "No ART start to compare."


def room_for_improvement(rows: list[dict[str, str]]) -> str:
    """How far above the convex lower bound ``J_CVX`` the SCvx* runs from CVX end, per mode:
    the most any warm start can gain."""
    j_cvx = column(rows, "j_cvx")
    parts = []
    for mode in MODES:
        ok = column(rows, f"{mode}_cvx_converged") == 1.0
        excess = 100.0 * (column(rows, f"{mode}_cvx_cost") - j_cvx) / j_cvx
        c = column(rows, f"{mode}_c_cvx_t1")
        parts.append(
            f"{label(mode, 'cvx')}: converged on {int(ok.sum())} of {len(rows)} instances and "
            f"ends on average {rep.fmt(mean_over(excess, ok))}% above J_CVX "
            f"(median {rep.fmt(float(np.median(excess[ok])) if ok.any() else math.nan)}%; "
            f"within 0.1% of J_CVX on {rep.fmt(100.0 * mean_over(excess < 0.1, ok))}% of them), "
            f"although its CVX warm start violates passive safety (C_CVX(t_1) > 0) on "
            f"{rep.fmt(100.0 * mean_over(c > 0, np.isfinite(c)))}% of the instances."
        )
    return "\n\n".join(parts) + (
        "\n\nThe improvement ratio divides by J_SCP,CVX - J_CVX: where that is small, a warm "
        "start has little to gain and the ratio moves a lot with a few instances. The "
        "infeasibility rate counts every instance."
    )


def discussion(out: Path) -> tuple[str, str] | None:
    """The hand-written ``OUT/discussion.md`` (what was measured, after the run, to explain
    the differences from the paper) as a report section, when there is one."""
    path = out / DISCUSSION_NAME
    if not path.is_file():
        return None
    return ("Why our numbers differ from the paper's (written after the run)", path.read_text())


def model_table(checkpoints: tuple[Any, ...]) -> str:
    """Frame, parameters, epochs and losses of each model beside the paper's."""
    table = [
        [
            (ck.frame or "?").upper(),
            f"{sum(p.numel() for p in ck.model.parameters()):,}",
            "{} layers, {} heads, {} wide".format(
                *(getattr(ck.config, k, "?") for k in ("n_layer", "n_head", "n_embd"))
            ),
            ck.metrics.get("epoch", "?"),
            rep.fmt(ck.metrics.get("best_val_loss", math.nan)),
        ]
        for ck in checkpoints
    ]
    table.append(["paper (both)", "n/a", "6 layers, 6 heads", "n/a", "n/a"])
    return rep.markdown_table(
        ("model", "parameters", "GPT", "epochs", "best validation loss"), table
    ) + (
        "\n\nThe paper trains on 90% of N_d = 115,000 trajectories per dataset; ours on the "
        "training split of the dataset above (commands in 'How the data and models were made')."
    )


def _threshold_table(mode: str, frames: tuple[str, ...], stats: list[dict]) -> str:
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
    return rep.markdown_table(header, table)


def _outcome_table(rows: list[dict[str, str]], mode: str, frames: tuple[str, ...]) -> str:
    """SCvx* statuses per warm start (the infeasibility rate split by cause)."""
    counts = {s: status_counts(rows, mode, s) for s in sources(frames)}
    statuses = sorted({k for c in counts.values() for k in c})

    def cell(n: int) -> str:
        return f"{n} ({100.0 * n / len(rows):.0f}%)"

    table = [
        [label(mode, s), *(cell(counts[s].get(k, 0)) for k in statuses)] for s in sources(frames)
    ]
    return rep.markdown_table(("warm start", *statuses), table)


def _check_table(rows: list[dict[str, str]], mode: str, frames: tuple[str, ...]) -> str:
    """Per model: the Eq. 8 errors of ART's own guesses and what the accepted ones gave."""
    table = []
    for s in sources(frames)[1:]:
        e_r = 100.0 * column(rows, f"{mode}_{s}_E_R")
        e_c = column(rows, f"{mode}_{s}_E_C")
        accepted = column(rows, f"{mode}_{s}_would_accept") == 1.0
        diff = column(rows, f"{mode}_cvx_cost") - column(rows, f"{mode}_{s}_cost")
        conv = column(rows, f"{mode}_{s}_converged") == 1.0
        cvx_conv = column(rows, f"{mode}_cvx_converged") == 1.0
        finite = np.isfinite(e_r) & np.isfinite(e_c)
        table.append(
            [
                label(mode, s),
                f"{int(accepted.sum())} / {len(rows)}",
                rep.fmt(float(np.median(e_r[finite])) if finite.any() else math.nan),
                rep.fmt(float(np.median(e_c[finite])) if finite.any() else math.nan),
                rep.fmt(100.0 * mean_over(e_c == 0.0, finite)),
                rep.fmt(100.0 * mean_over(e_r < 0.0, finite)),
                f"{int((accepted & conv).sum())} vs {int((accepted & cvx_conv).sum())}",
                rep.fmt(1e3 * mean_over(diff, accepted & conv & cvx_conv)),
            ]
        )
    header = (
        "ART model",
        "guesses the check accepts",
        "median 100 E_R",
        "median E_C",
        "E_C = 0 [%]",
        "E_R < 0 [%]",
        "accepted ones: ART vs CVX converged",
        "accepted ones: mean J_SCP,CVX - J_SCP,ART [mm/s]",
    )
    return rep.markdown_table(header, table) + (
        "\n\nWith the check a rejected guess falls back to CVX, so its SCvx* run repeats "
        "PS-CVX's: the check keeps ART's outcome only on the accepted instances."
    )


def _comparisons(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...], stats: list[dict]
) -> list[rep.Comparison]:
    """The paper's claims about Figs. 5-6 beside our numbers, per ART model."""
    C, letter, every = rep.Comparison, MODES[mode], stats[0]
    populated = [st for st in stats if st["count"] > 0]
    hardest = populated[-1] if populated else every
    out = []
    for s in sources(frames)[1:]:
        best = max(
            (st[f"{s}_improvement"] for st in stats if math.isfinite(st[f"{s}_improvement"])),
            default=math.nan,
        )
        diff = cost_differences(rows, mode, s)
        small = rep.fmt(100.0 * float(np.mean(np.abs(diff) < 0.25))) if diff.size else "n/a"
        span = (
            f"[{rep.fmt(float(diff.min()))}, {rep.fmt(float(diff.max()))}]" if diff.size else "n/a"
        )
        name, cvx = label(mode, s), f"PS-CVX-{letter}"

        def pair(st: dict, key: str, digits: int = 3, s: str = s) -> str:
            return f"{rep.fmt(st[f'{s}_{key}'], digits)} vs {rep.fmt(st[f'cvx_{key}'], digits)}"

        out += [
            C(quantity=f"{name}: largest improvement ratio over the C_CVX bins [%]",
              paper="up to 35" if letter == "D" else "up to 22", ours=rep.fmt(best),
              note=f"all instances: {rep.fmt(every[f'{s}_improvement'])}%"),
            C(quantity=f"{name} vs {cvx}: J_SCP - J_CVX (all) [m/s]", paper="lower with ART",
              ours=f"{rep.fmt(every[f'{s}_gap'])} vs {rep.fmt(every[f'{s}_cvx_gap'])}",
              note="instances where both converged"),
            C(quantity=f"{name} vs {cvx}: SCP iterations (all)", paper="fewer with ART",
              ours=f"{rep.fmt(every[f'{s}_iterations'])} vs {rep.fmt(every['cvx_iterations'])}"),
            C(quantity=f"{name} vs {cvx}: warm-start time (all) [s]",
              paper="longer with ART (WS-ART > CVX)",
              ours=f"{rep.fmt(every[f'{s}_ws_time'], 2)} vs {rep.fmt(every['cvx_ws_time'], 2)}",
              note="ART's includes the CVX solve it is conditioned on"),
            C(quantity=f"{name} vs {cvx}: runtime, warm start + SCP (all) [s]",
              paper="comparable or shorter with ART",
              ours=f"{rep.fmt(every[f'{s}_time'], 2)} vs {rep.fmt(every['cvx_time'], 2)}"),
            C(quantity=f"{name} vs {cvx}: infeasibility rate (all) [%]",
              paper="lower with ART" + (" (CVX high in the chance case)" if letter == "C" else ""),
              ours=pair(every, "infeasible_pct"),
              note="without the check (as the paper's Figs. 5-6); "
              + _discordant_note(rows, mode, s)),
            C(quantity=f"{name} vs {cvx}: infeasibility rate at C_CVX >= {hardest['x']} [%]",
              paper="ART stays flat where CVX rises",
              ours=pair(hardest, "infeasible_pct"),
              note=f"n = {hardest['count']}"),
            C(quantity=f"{name}: |J_SCP,CVX - J_SCP,ART| < 0.25 m/s [% of instances]",
              paper="most", ours=small, note=f"n = {diff.size} (both converged)"),
            C(quantity=f"{name}: range of J_SCP,CVX - J_SCP,ART [m/s]",
              paper="some beyond +-1", ours=span),
        ]  # fmt: skip
    return out


def _checked_comparisons(
    mode: str,
    frames: tuple[str, ...],
    stats: list[dict],
    checked: list[dict],
    checked_rows: list[dict[str, str]],
) -> list[rep.Comparison]:
    """Infeasibility and improvement with the check beside the raw ART warm start (Fig. 10)."""
    letter, out = MODES[mode], []
    for s in sources(frames)[1:]:
        out.append(
            rep.Comparison(
                quantity=f"{label(mode, s)} with the check: infeasibility rate / improvement "
                f"ratio (all) [%], vs PS-CVX-{letter}'s infeasibility",
                paper="n/a (Fig. 10: the check removes the large deteriorations)",
                ours=f"{rep.fmt(checked[0][f'{s}_infeasible_pct'])} / "
                f"{rep.fmt(checked[0][f'{s}_improvement'])}, vs "
                f"{rep.fmt(stats[0]['cvx_infeasible_pct'])}",
                note=f"guesses accepted: {rep.fmt(checked[0][f'{s}_accepted_pct'])}%; "
                + _discordant_note(checked_rows, mode, s),
            )
        )
    return out


def _frame_comparisons(rows: list[dict[str, str]], frames: tuple[str, ...]) -> list[rep.Comparison]:
    """The paper: the ROE-trained model slightly ahead of the RTN-trained one."""
    out = []
    for mode in MODES:
        every = bin_stats(rows, mode, frames, np.ones(len(rows), dtype=bool))
        values = ", ".join(
            f"{f.upper()} {rep.fmt(every[f'art_{f}_improvement'])}% / "
            f"{rep.fmt(every[f'art_{f}_infeasible_pct'])}%"
            for f in frames
        )
        out.append(
            rep.Comparison(
                quantity=f"RTN vs ROE model ({mode}): improvement ratio / infeasibility (all)",
                paper="similar; ROE slightly better",
                ours=values,
            )
        )
    return out


def _figure(
    rows: list[dict[str, str]], mode: str, frames: tuple[str, ...], stats: list[dict], out: Path
) -> tuple[str, str]:
    """The paper's six panels: suboptimality, improvement ratio, iterations, runtime,
    infeasibility rate (over ``C_CVX(t_1) >= x``) and the histogram of the cost difference."""
    x = np.array([s["x"] for s in stats], dtype=float)
    fig, grid = rep.new_figure(ncols=3, nrows=2, width=15.0, height=8.0)
    axes = grid.ravel()
    colors = dict(zip(sources(frames), ("tab:blue", "tab:red", "tab:orange"), strict=False))
    panels = (
        ("gap", "J_SCP - J_CVX [m/s]", sources(frames)),
        ("improvement", "suboptimality improvement ratio [%]", sources(frames)[1:]),
        ("iterations", "SCP iterations", sources(frames)),
        ("time", "runtime: warm start + SCP [s] (dotted: warm start)", sources(frames)),
        ("infeasible_pct", "infeasibility rate [%]", sources(frames)),
    )
    for ax, (key, ylabel, shown) in zip(axes[:5], panels, strict=True):
        for s in shown:
            ax.plot(
                x, [st[f"{s}_{key}"] for st in stats], "o-", color=colors[s], label=label(mode, s)
            )
            if key == "time":
                ax.plot(x, [st[f"{s}_ws_time"] for st in stats], ":", color=colors[s])
        ax.set_xlabel("C_CVX(t_1) >= x")
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=7)
        plot_counts(ax, x, stats)
    for s in sources(frames)[1:]:
        diff = cost_differences(rows, mode, s)
        if diff.size:
            axes[5].hist(diff, bins=20, alpha=0.6, color=colors[s], label=label(mode, s))
            for v in (diff.min(), diff.max()):
                axes[5].axvline(v, color="red", ls=":")
    axes[5].set_xlabel("J_SCP,CVX - J_SCP,ART [m/s]")
    axes[5].set_ylabel("instances")
    if axes[5].get_legend_handles_labels()[0]:
        axes[5].legend(fontsize=7)
    number = "5" if mode == "deterministic" else "6"
    file = rep.save_figure(fig, out / f"fig{number}_{mode}.png")
    return file, f"Fig. {number}: {mode} passive safety, SCvx* from CVX and ART"
