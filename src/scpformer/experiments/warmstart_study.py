"""``art-warmstart``: SCP warm-started by CVX-TPBVP, CVX and ART (ART paper Sec. 5, Figs. 4-6).

On test-split instances of a rendezvous dataset (rebuilt from theta with the dataset's
scenario and solver configuration), each worker solves Problem 1 (CVX-TPBVP) and Problem 2
(CVX), generates ART's guess with Algorithm 2 conditioned on ``R(t_1) = -J_CVX``,
``C(t_1) = 0`` (no acceptance check: the ART paper always warm-starts with ART), and runs
the SCP of Problem 3 from each of the three. Per instance and warm start it records the SCP
cost, status, iterations, cost after each iteration, warm-start time and SCP time.

The analysis follows the paper's figures: every metric is an average over the test instances
whose ``C_CVX(t_1)`` exceeds the value on the x-axis (the paper's grey dashed line is that
count), plus disjoint bins for the ranges the text quotes:

* suboptimality gap ``J_SCP - J_CVX`` [mm/s] (``J_CVX``, the cost of Problem 2, is a lower
  bound of Problem 3; it and ``C_CVX(t_1)`` come from a solve of Problem 2 to tight
  tolerances, :func:`~scpformer.problems.rendezvous.scp.convex_lower_bound`, not from the CVX
  warm start's, whose cost can lie 1e-4 above the optimum) and ART's improvement over warm
  start X,
  ``100 (gap_X - gap_ART) / gap_X`` of the bin means (Fig. 4);
* SCP iterations, and the cost after each iteration as ``100 J_CVX / J_k`` for
  ``C_CVX(t_1) > 1``, the last iterate held after convergence (Fig. 5);
* warm-start and SCP runtime (Fig. 6 left): ART's warm-start time includes the CVX solve that
  sets ``R(t_1)``; the generation alone is reported too;
* infeasibility rate: SCP runs that return no solution (no subproblem solved) (Fig. 6 right).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.data.rendezvous_family import RendezvousDataConfig
from scpformer.experiments import report as rep
from scpformer.experiments.paired import Outcomes, paired_table
from scpformer.experiments.runner import (
    KEY,
    InstanceTask,
    ModelSolver,
    RunOptions,
    column,
    join_series,
    open_study,
    result_columns,
    select_and_record,
    series,
    solve_tasks,
    theta_tasks,
)

NAME = "art-warmstart"
REPRODUCES = "ART paper Figs. 4-6 (SCP warm-started by CVX-TPBVP, CVX and ART)"
WARMSTARTS = ("tpbvp", "convex", "art")
LABELS = {"tpbvp": "CVX-TPBVP", "convex": "CVX", "art": "ART"}
COLORS = {"tpbvp": "tab:green", "convex": "tab:blue", "art": "tab:red"}
THRESHOLDS = (-1, 0, 5, 10, 15, 20, 25, 30, 35, 40)  # C_CVX(t_1) > x; -1: every instance
RANGES = ((0, 0), (1, 9), (10, 19), (20, 29), (30, 40), (41, 10**6))  # disjoint bins
MM = 1e3  # m/s -> mm/s
INTERVAL_LEVEL = 0.9  # two-sided level of the bootstrap intervals of the improvement rows
BOOTSTRAP_DRAWS = 2000  # resamples per interval (seeded: the report is reproducible)
J_TOL = 1e-6  # the SCP's cost tolerance (Eq. 19, Table 1) [m/s]: two costs within it tie
PER_WS = (
    "ws_time",
    "ws_cost",
    "ws_ctg",
    "ws_waypoint_miss_m",
    "status",
    "cost",
    "iterations",
    "scp_time",
    "feasible",
    "history",
)
COLUMNS = result_columns(
    "c_cvx_t1",
    "j_cvx",
    "art_generation_s",
    *(f"{ws}_{name}" for ws in WARMSTARTS for name in PER_WS),
)


class WarmstartSolver(ModelSolver):
    """Per-instance work of ``art-warmstart`` (runs in the executor's workers)."""

    def __init__(self, checkpoint: Path, data_config: dict[str, Any], verify: bool) -> None:
        super().__init__([checkpoint], data_config)
        self.verify = verify

    def warm_up(self) -> None:
        from scpformer.problems.rendezvous.subproblems import compiled_subproblem

        super().warm_up()
        config = RendezvousDataConfig.from_dict(self.data_config)
        sc = config.scenario
        for kind in ("tpbvp", "convex", "scp"):  # compiled before any solve is timed
            compiled_subproblem(kind, sc.n_nodes, sc.n_waypoint, config.solver.scp.solver)

    def solve(self, task: InstanceTask) -> dict[str, Any]:
        from scpformer.problems.rendezvous.problem import boundary_data, linear_model, solve
        from scpformer.problems.rendezvous.scp import convex_lower_bound
        from scpformer.problems.rendezvous.warmstart import initial_constraint_to_go
        from scpformer.warmstart import (
            ArtWarmStart,
            PrecomputedWarmStart,
            RendezvousConvexWarmStart,
        )

        config = RendezvousDataConfig.from_dict(self.data_config)
        instance = self.instance(task.theta)
        guesses = {
            kind: RendezvousConvexWarmStart(kind, config.solver).guess(instance)
            for kind in WARMSTARTS[:2]
        }
        (ckpt,) = self.models
        art = ArtWarmStart(
            ckpt.model,
            ckpt.normalization,
            frame=ckpt.frame,
            acceptance=None,
            fallback=PrecomputedWarmStart(guesses["convex"]),
        )
        guesses["art"] = art.guess(instance)
        bound = convex_lower_bound(instance, config.solver)
        row: dict[str, Any] = {
            KEY: task.index,
            "c_cvx_t1": initial_constraint_to_go(instance, bound),
            "j_cvx": bound.cost,
            "art_generation_s": guesses["art"].record.details.get("generation_s", math.nan),
            "status": "ok",
            "message": "",
        }
        x_wp = boundary_data(instance, linear_model(instance)).x_wp
        kw = instance.scenario.n_waypoint
        for ws, guess in guesses.items():
            if guess.trajectory is not None:  # the trust region (Eq. 17) must reach x_wp
                miss = float(np.linalg.norm(np.asarray(guess.trajectory.x)[kw] - x_wp))
                row[f"{ws}_ws_waypoint_miss_m"] = miss
            solution = solve(
                instance, "scp", PrecomputedWarmStart(guess), config.solver, verify=self.verify
            )
            row.update(
                {
                    f"{ws}_ws_time": guess.record.time_s,
                    f"{ws}_ws_cost": guess.record.cost,
                    f"{ws}_ws_ctg": guess.record.constraint_to_go,
                    f"{ws}_status": solution.status.value,
                    f"{ws}_cost": solution.cost,
                    f"{ws}_iterations": solution.iterations,
                    f"{ws}_scp_time": solution.timing.total if solution.timing else math.nan,
                    f"{ws}_feasible": solution.trajectory is not None,
                    f"{ws}_history": join_series(r.cost for r in solution.history),
                }
            )
        return row


# ======================================================================================
# the run
# ======================================================================================
def run(options: RunOptions, *, command: str = "", name: str = NAME, verify: bool = False) -> Path:
    """Run ``art-warmstart`` into ``options.out``; returns the report's path.

    ``verify`` replays every SCP solution through the nonlinear propagator (off: the paper
    judges the SCP in its linear model).
    """
    study = open_study(options, "rendezvous", models=1)
    (ckpt,) = study.checkpoints
    positions, settings = select_and_record(
        options, study, experiment=NAME, verify=verify, model_kind=ckpt.kind, frame=ckpt.frame,
        conditioning="R(t_1) = -J_CVX, C(t_1) = 0, Algorithm 2, no acceptance check",
    )  # fmt: skip
    solver = WarmstartSolver(study.models[0], study.manifest.config, verify)
    rows = solve_tasks(solver, theta_tasks(study.data, positions), options, COLUMNS)
    zeta_1 = float(study.manifest.config["solver"]["scp"]["zeta_1"])
    report = analyse(rows, options.out, zeta_1)
    report.command, report.settings, report.provenance = command, settings, study.provenance()
    finished = (
        f"{len(rows)} of {positions.size} selected test instances finished (failed or "
        f"missing: {positions.size - len(rows)})."
    )
    report.sections.insert(0, ("Instances", finished))
    return report.write(options.out)


# ======================================================================================
# analysis
# ======================================================================================
@dataclass(frozen=True)
class Columns:
    """The per-instance results as arrays (one entry per instance)."""

    c: np.ndarray  # C_CVX(t_1)
    j_cvx: np.ndarray  # lower bound [m/s]
    cost: dict[str, np.ndarray]  # SCP cost per warm start [m/s]
    feasible: dict[str, np.ndarray]  # bool
    iterations: dict[str, np.ndarray]
    ws_time: dict[str, np.ndarray]
    scp_time: dict[str, np.ndarray]
    history: dict[str, list[np.ndarray]]
    generation: np.ndarray  # ART generation alone [s]
    ws_cost: dict[str, np.ndarray]  # the guesses' own cost [m/s]
    waypoint_miss: dict[str, np.ndarray]  # |x_guess(t_Nwp) - x_wp| [m]

    @classmethod
    def from_rows(cls, rows: list[dict[str, str]]) -> Columns:
        def per(name: str) -> dict[str, np.ndarray]:
            return {ws: column(rows, f"{ws}_{name}") for ws in WARMSTARTS}

        return cls(
            c=column(rows, "c_cvx_t1"),
            j_cvx=column(rows, "j_cvx"),
            cost=per("cost"),
            feasible={ws: v == 1.0 for ws, v in per("feasible").items()},
            iterations=per("iterations"),
            ws_time=per("ws_time"),
            scp_time=per("scp_time"),
            history={ws: [series(r[f"{ws}_history"]) for r in rows] for ws in WARMSTARTS},
            generation=column(rows, "art_generation_s"),
            ws_cost=per("ws_cost"),
            waypoint_miss=per("ws_waypoint_miss_m"),
        )

    def all_feasible(self) -> np.ndarray:
        """Instances where every warm start's SCP returned a solution (cost comparisons)."""
        ok = np.isfinite(self.j_cvx)
        for ws in WARMSTARTS:
            ok &= self.feasible[ws] & np.isfinite(self.cost[ws])
        return ok

    def gap(self, ws: str) -> np.ndarray:
        """Suboptimality gap ``J_SCP - J_CVX`` [mm/s]."""
        return MM * (self.cost[ws] - self.j_cvx)


def mean_over(values: np.ndarray, mask: np.ndarray) -> float:
    """Mean of ``values[mask]`` (NaN when ``mask`` selects nothing)."""
    return float(np.mean(values[mask])) if mask.any() else math.nan


def relative_gap(cols: Columns, ws: str, mask: np.ndarray) -> float:
    """Mean ``100 (J_SCP - J_CVX) / J_CVX`` [%] of warm start ``ws`` over ``mask``."""
    both = mask & cols.all_feasible()
    return mean_over(100.0 * (cols.cost[ws] - cols.j_cvx) / cols.j_cvx, both)


def bin_stats(cols: Columns, mask: np.ndarray) -> dict[str, float]:
    """Every figure's metric over the instances in ``mask``."""
    both = mask & cols.all_feasible()
    out: dict[str, float] = {"count": int(mask.sum()), "count_feasible": int(both.sum())}
    for ws in WARMSTARTS:
        out[f"{ws}_gap"] = mean_over(cols.gap(ws), both)
        out[f"{ws}_iterations"] = mean_over(cols.iterations[ws], both)
        out[f"{ws}_ws_time"] = mean_over(cols.ws_time[ws], mask)
        out[f"{ws}_scp_time"] = mean_over(cols.scp_time[ws], mask)
        out[f"{ws}_infeasible_pct"] = 100.0 * mean_over(~cols.feasible[ws], mask)
    for ws in WARMSTARTS[:2]:
        gap = out[f"{ws}_gap"]
        out[f"improvement_vs_{ws}"] = 100.0 * (gap - out["art_gap"]) / gap if gap > 0 else math.nan
    out["art_generation_s"] = mean_over(cols.generation, mask)
    return out


@dataclass(frozen=True)
class Bootstrap:
    """How :func:`bootstrap_interval` resamples: the interval's two-sided ``level``, the
    number of resamples ``draws`` and the ``seed`` of their draw."""

    level: float = INTERVAL_LEVEL
    draws: int = BOOTSTRAP_DRAWS
    seed: int = 0


def improvement_interval(
    cols: Columns, ws: str, mask: np.ndarray, bootstrap: Bootstrap = Bootstrap()
) -> tuple[float, float]:
    """Percentile bootstrap interval of :func:`bin_stats`' ``improvement_vs_{ws}`` over ``mask``.

    Each resample gives ``100 (gap_ws - gap_ART) / gap_ws`` of its means (resamples with
    ``gap_ws <= 0`` are dropped). The gaps are a fraction of a mm/s, so a few instances move
    the ratio: the interval says how far. See :func:`bootstrap_interval`.
    """

    def ratio(picks: np.ndarray) -> np.ndarray:
        reference = cols.gap(ws)[picks].mean(axis=1)
        art = cols.gap("art")[picks].mean(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(reference > 0.0, 100.0 * (reference - art) / reference, np.nan)

    return bootstrap_interval(cols, mask, ratio, bootstrap)


def iterations_saved_interval(
    cols: Columns, mask: np.ndarray, bootstrap: Bootstrap = Bootstrap()
) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean SCP iterations saved by ART against CVX
    (``iterations_CVX - iterations_ART``, paired per instance) over ``mask``."""

    def saved(picks: np.ndarray) -> np.ndarray:
        return (cols.iterations["convex"][picks] - cols.iterations["art"][picks]).mean(axis=1)

    return bootstrap_interval(cols, mask, saved, bootstrap)


def bootstrap_interval(
    cols: Columns,
    mask: np.ndarray,
    statistic: Callable[[np.ndarray], np.ndarray],
    bootstrap: Bootstrap = Bootstrap(),
) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic`` over the instances of ``mask`` where all
    three SCP runs solved (Efron & Tibshirani 1993, Ch. 13).

    The instances are resampled with replacement ``bootstrap.draws`` times (seeded);
    ``statistic`` maps the (draws, n) instance indices of the resamples to one value per
    resample (NaN to drop it), and the interval is the central ``bootstrap.level`` of those
    values. ``(nan, nan)`` with fewer
    than two instances or no finite value.
    """
    chosen = np.flatnonzero(mask & cols.all_feasible())
    if chosen.size < 2:
        return math.nan, math.nan
    rng = np.random.default_rng(bootstrap.seed)
    picks = chosen[rng.integers(0, chosen.size, (bootstrap.draws, chosen.size))]
    values = statistic(picks)
    values = values[np.isfinite(values)]
    if not values.size:
        return math.nan, math.nan
    level = bootstrap.level
    lo, hi = np.percentile(values, [50.0 * (1.0 - level), 50.0 * (1.0 + level)])
    return float(lo), float(hi)


def cumulative(cols: Columns) -> list[dict[str, float]]:
    """:func:`bin_stats` over ``C_CVX(t_1) > x`` for x in :data:`THRESHOLDS`."""
    return [{"x": x, **bin_stats(cols, cols.c > x)} for x in THRESHOLDS]


def disjoint(cols: Columns) -> list[dict[str, Any]]:
    """:func:`bin_stats` over the ranges of :data:`RANGES`."""
    return [
        {"range": (lo, hi), **bin_stats(cols, (cols.c >= lo) & (cols.c <= hi))} for lo, hi in RANGES
    ]


def convergence(cols: Columns, k_max: int) -> dict[str, np.ndarray]:
    """Mean ``100 J_CVX / J_k`` after iteration k = 1..k_max for ``C_CVX(t_1) > 1``."""
    mask = (cols.c > 1) & cols.all_feasible()
    out = {}
    for ws in WARMSTARTS:
        curves = []
        for i in np.flatnonzero(mask):
            h = cols.history[ws][i]
            if h.size == 0:
                continue
            h = np.fmin.accumulate(np.where(np.isfinite(h), h, np.inf))  # best so far
            padded = np.concatenate([h, np.full(max(0, k_max - h.size), h[-1])])[:k_max]
            curves.append(100.0 * cols.j_cvx[i] / padded)
        out[ws] = np.mean(curves, axis=0) if curves else np.full(k_max, math.nan)
    return out


def analyse(rows: list[dict[str, str]], out: Path, zeta_1: float = math.inf) -> rep.Report:
    """Tables, figures and the paper-vs-ours rows of the finished instances."""
    report = rep.Report(name=NAME, reproduces=REPRODUCES, command="", settings={})
    if not rows:
        report.sections.append(("Results", "No instance finished."))
        return report
    # instance order, not the order the workers finished in: the bootstrap resamples positions
    rows = sorted(rows, key=lambda row: int(row["index"]))
    cols = Columns.from_rows(rows)
    cum, bins = cumulative(cols), disjoint(cols)
    report.figures += _figures(cols, cum, out)
    report.sections.append(("Results by C_CVX(t_1) > x (the paper's curves)", _table(cum, "x")))
    report.sections.append(("Results in disjoint C_CVX(t_1) ranges", _table(bins, "range")))
    report.sections.append(("Instance by instance against CVX", paired_text(rows)))
    report.comparisons += _comparisons(cols, cum)
    report.sections.insert(0, ("Reading these numbers", _caveats(cols, zeta_1)))
    return report


def outcomes(rows: list[dict[str, str]], ws: str) -> Outcomes:
    """Warm start ``ws``'s whole path per instance: the guess's time plus the SCP's, its
    iterations, converged or not, and its cost (NaN without a trajectory)."""

    def col(name: str) -> np.ndarray:
        return np.array([float(r.get(f"{ws}_{name}") or "nan") for r in rows])

    solved = np.array([r.get(f"{ws}_status") == "converged" for r in rows], dtype=bool)
    return Outcomes(time=col("ws_time") + np.nan_to_num(col("scp_time")),
                    iterations=col("iterations"), solved=solved, cost=col("cost"))  # fmt: skip


def paired_text(rows: list[dict[str, str]]) -> str:
    """ART and CVX-TPBVP against CVX, the strongest classical start, draw by draw
    (:mod:`.paired`); a cost difference within the SCP's J_tol (1e-6 m/s) ties."""
    base = outcomes(rows, "convex")
    return "\n\n".join(
        f"**{LABELS[ws]} against CVX**\n\n"
        + paired_table(LABELS[ws], outcomes(rows, ws), "CVX", base, cost_tie=J_TOL)
        for ws in ("art", "tpbvp")
    ) + ("\n\nWall time of the whole path: the guess (ART: its convex solve for "
         "R(t_1) = -J_CVX and the rollout) and every SCP iteration.")  # fmt: skip


def _caveats(cols: Columns, zeta_1: float) -> str:
    """What the cost comparisons rest on, and why ART-started SCP runs fail."""
    positive = cols.c > 0
    compared = positive & cols.all_feasible()
    room = relative_gap(cols, "convex", positive)
    far = {ws: 100.0 * float(np.mean(cols.waypoint_miss[ws] > zeta_1)) for ws in WARMSTARTS}
    guesses = ", ".join(
        f"{LABELS[ws]} {rep.fmt(MM * float(np.nanmean(cols.ws_cost[ws])))} mm/s"
        f" ({rep.fmt(far[ws])}% beyond zeta_1)"
        for ws in WARMSTARTS
    )
    return (
        f"Cost comparisons (gaps, improvements, iterations) use the instances where all three "
        f"SCP runs returned a solution: {int(compared.sum())} of {int(positive.sum())} with "
        f"C_CVX(t_1) > 0. There the SCP started from CVX ends {rep.fmt(room)}% above the convex "
        "lower bound J_CVX on average, so the improvement ratios divide small differences and "
        "move a lot with a few instances; read them with the bin counts. The infeasibility "
        "rate counts every instance.\n\n"
        f"The first SCP subproblem keeps nodes 0..N_wp within zeta_1 = {rep.fmt(zeta_1)} m of "
        "the guess (Eq. 17) and fixes the waypoint state, so a guess whose waypoint state is "
        "farther than zeta_1 from it makes that subproblem infeasible. Mean guess cost and "
        f"share of guesses beyond zeta_1: {guesses}; J_CVX averages "
        f"{rep.fmt(MM * float(np.nanmean(cols.j_cvx)))} mm/s."
    )


def _table(stats: list[dict[str, Any]], key: str) -> str:
    header = [
        f"C_CVX {'>' if key == 'x' else 'in'}",
        "n (all 3 solved)",
        *(f"gap {LABELS[ws]} [mm/s]" for ws in WARMSTARTS),
        "ART impr. vs CVX [%]",
        "ART impr. vs TPBVP [%]",
        *(f"iter. {LABELS[ws]}" for ws in WARMSTARTS),
        *(f"WS+SCP {LABELS[ws]} [s]" for ws in WARMSTARTS),
        *(f"infeas. {LABELS[ws]} [%]" for ws in WARMSTARTS),
    ]
    rows = []
    for s in stats:
        label = (
            ("all" if s["x"] < 0 else s["x"])
            if key == "x"
            else (
                f"[{s['range'][0]}, {s['range'][1]}]"
                if s["range"][1] < 10**6
                else f">= {s['range'][0]}"
            )
        )
        rows.append(
            [
                label,
                f"{s['count']} ({s['count_feasible']})",
                *(rep.fmt(s[f"{ws}_gap"]) for ws in WARMSTARTS),
                rep.fmt(s["improvement_vs_convex"]),
                rep.fmt(s["improvement_vs_tpbvp"]),
                *(rep.fmt(s[f"{ws}_iterations"]) for ws in WARMSTARTS),
                *(
                    f"{rep.fmt(s[f'{ws}_ws_time'], 2)}+{rep.fmt(s[f'{ws}_scp_time'], 2)}"
                    for ws in WARMSTARTS
                ),
                *(rep.fmt(s[f"{ws}_infeasible_pct"]) for ws in WARMSTARTS),
            ]
        )
    return rep.markdown_table(header, rows)


def _curve_extreme(
    cum: list[dict], value: Any, lo: int, hi: int, pick: Any = max
) -> tuple[float, int, int]:
    """``pick`` of ``value(point)`` over the paper's curve points ``C_CVX(t_1) > x``, ``x`` in
    ``[lo, hi]``: (value, its x, its instance count). NaN points are skipped."""
    points = [(float(value(s)), s["x"], s["count_feasible"]) for s in cum if lo <= s["x"] <= hi]
    points = [p for p in points if np.isfinite(p[0])]
    if not points:
        return math.nan, lo, 0
    return pick(points, key=lambda p: p[0])


def _comparisons(cols: Columns, cum: list[dict]) -> list[rep.Comparison]:
    """The paper's claims beside ours, read as the paper reads its Figs. 4-6.

    Each point of those figures averages the instances with ``C_CVX(t_1) > x`` (the grey
    dashed count), so "more than 20% for all C_CVX(t_1) > 0" is the least improvement over
    the points ``x >= 0`` and "up to 80% in the range [30, 40]" the largest over the points
    ``x`` in [30, 40]. The disjoint bins of the second table are a stricter view.
    """
    every = next(s for s in cum if s["x"] < 0)
    share = 100.0 * float(np.mean(cols.c > 0))

    def least(ws: str) -> tuple[str, str]:
        value, x, n = _curve_extreme(cum, lambda s: s[f"improvement_vs_{ws}"], 0, 10**6, min)
        where = f"least over the points x >= 0 (at x = {x}, n = {n}"
        return rep.fmt(value), where + _interval_note(cols, ws, x)

    def most(value: Any, ws: str | None = None) -> tuple[str, str]:
        best, x, n = _curve_extreme(cum, value, 30, 40)
        where = f"largest over the points x = 30..40 (at x = {x}, n = {n}"
        return rep.fmt(best), where + (_interval_note(cols, ws, x) if ws else ")")

    vs_cvx, vs_tpbvp = least("convex"), least("tpbvp")
    up_cvx = most(lambda s: s["improvement_vs_convex"], "convex")
    up_tpbvp = most(lambda s: s["improvement_vs_tpbvp"], "tpbvp")
    saved_iterations = most(lambda s: s["convex_iterations"] - s["art_iterations"])
    fewest_saved = least_saved_iterations(cols, cum)
    saved_time = most(lambda s: s["convex_scp_time"] - s["art_scp_time"])
    total = " / ".join(rep.fmt(every[f"{ws}_ws_time"] + every[f"{ws}_scp_time"])
                       for ws in ("convex", "tpbvp", "art"))  # fmt: skip
    infeasible = " / ".join(rep.fmt(every[f"{ws}_infeasible_pct"]) for ws in WARMSTARTS)
    rows = (  # quantity, the paper's claim, ours, note
        ("share of test instances with C_CVX(t_1) > 0 [%]", "~50", rep.fmt(share),
         f"{cols.c.size} instances"),
        ("gap of the CVX-started SCP to J_CVX, C_CVX > 0 [% of J_CVX]", "Fig. 4 only",
         rep.fmt(relative_gap(cols, "convex", cols.c > 0)), "the room ART can improve on"),
        ("ART improvement of the gap vs CVX, every C_CVX(t_1) > x, x >= 0 [%]", "> 20", *vs_cvx),
        ("ART improvement of the gap vs CVX-TPBVP, every C_CVX(t_1) > x, x >= 0 [%]", "> 20",
         *vs_tpbvp),
        ("ART improvement vs CVX, C_CVX(t_1) > x, x in [30, 40] [%]", "up to 80", *up_cvx),
        ("ART improvement vs CVX-TPBVP, C_CVX(t_1) > x, x in [30, 40] [%]", "up to ~90",
         *up_tpbvp),
        ("SCP iterations saved by ART vs CVX, every C_CVX(t_1) > x, x >= 0",
         "> 0 (fewer on average)", *fewest_saved),
        ("SCP iterations saved by ART vs CVX, C_CVX(t_1) > x, x in [30, 40]", "up to ~1.5",
         *saved_iterations),
        ("ART generation time (Algorithm 2) [s]", "~0.5 (GPU machine)",
         rep.fmt(every["art_generation_s"]), "mean, one instance per call, 1 thread"),
        ("convex warm start time (CVX) [s]", "~0.15", rep.fmt(every["convex_ws_time"]), "mean"),
        ("SCP time saved by ART vs CVX, C_CVX(t_1) > x, x in [30, 40] [s]", "up to 1",
         *saved_time),
        ("total time WS + SCP, CVX / CVX-TPBVP / ART [s]", "~2 each", total, "mean over all"),
        ("SCP infeasibility rate, CVX-TPBVP / CVX / ART [%]",
         "Fig. 6 only (no number in the text)", infeasible, ""),
    )  # fmt: skip
    return [rep.Comparison(quantity=q, paper=p, ours=o, note=n) for q, p, o, n in rows]


def least_saved_iterations(cols: Columns, cum: list[dict]) -> tuple[str, str]:
    """The fewest mean SCP iterations saved by ART against CVX over the points ``x >= 0``,
    with the 90% bootstrap interval of the paired difference at that point."""
    value, x, n = _curve_extreme(
        cum, lambda s: s["convex_iterations"] - s["art_iterations"], 0, 10**6, min
    )
    interval = _interval_text(*iterations_saved_interval(cols, cols.c > x))
    return rep.fmt(value), f"least over the points x >= 0 (at x = {x}, n = {n}{interval})"


def _interval_note(cols: Columns, ws: str, x: float) -> str:
    """``"; 90% bootstrap interval [lo, hi])"`` of the improvement at the point ``C_CVX > x``."""
    return _interval_text(*improvement_interval(cols, ws, cols.c > x)) + ")"


def _interval_text(lo: float, hi: float) -> str:
    """``"; 90% bootstrap interval [lo, hi]"``, or nothing when the interval is undefined."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return ""
    return f"; {round(100 * INTERVAL_LEVEL)}% bootstrap interval [{rep.fmt(lo)}, {rep.fmt(hi)}]"


def _plot_lines(ax: Any, x: np.ndarray, cum: list[dict], key: str, ylabel: str) -> None:
    for ws in WARMSTARTS:
        ax.plot(x, [s[f"{ws}_{key}"] for s in cum], "o-", color=COLORS[ws], label=LABELS[ws])
    ax.set_xlabel("C_CVX(t_1) > x")
    ax.set_ylabel(ylabel)


def plot_counts(ax: Any, x: np.ndarray, cum: list[dict]) -> None:
    """The paper's grey dashed line: instances with C_CVX(t_1) > x."""
    twin = ax.twinx()
    twin.plot(x, [s["count"] for s in cum], "--", color="grey", label="samples")
    twin.set_ylabel("test samples", color="grey")


def _figures(cols: Columns, cum: list[dict], out: Path) -> list[tuple[str, str]]:
    x = np.array([s["x"] for s in cum], dtype=float)
    files = []
    fig, (a, b) = rep.new_figure()
    _plot_lines(a, x, cum, "gap", "suboptimality gap J_SCP - J_CVX [mm/s]")
    a.legend()
    plot_counts(a, x, cum)
    for ws in WARMSTARTS[:2]:
        b.plot(
            x,
            [s[f"improvement_vs_{ws}"] for s in cum],
            "o-",
            color=COLORS[ws],
            label=f"ART vs {LABELS[ws]}",
        )
    b.axhline(0.0, color="black", lw=0.5)
    b.set_xlabel("C_CVX(t_1) > x")
    b.set_ylabel("ART improvement of the gap [%]")
    b.legend()
    plot_counts(b, x, cum)
    files.append(
        (
            rep.save_figure(fig, out / "fig4_cost.png"),
            "Fig. 4: suboptimality gap (left), ART's improvement (right)",
        )
    )
    fig, (a, b) = rep.new_figure()
    _plot_lines(a, x, cum, "iterations", "SCP iterations")
    a.legend()
    plot_counts(a, x, cum)
    k_max = max((h.size for ws in WARMSTARTS for h in cols.history[ws]), default=1)
    for ws, curve in convergence(cols, max(k_max, 1)).items():
        b.plot(np.arange(1, curve.size + 1), curve, "o-", color=COLORS[ws], label=LABELS[ws])
    b.set_xlabel("SCP iteration")
    b.set_ylabel("100 J_CVX / J_k [%] (C_CVX > 1)")
    b.legend()
    files.append(
        (
            rep.save_figure(fig, out / "fig5_iterations.png"),
            "Fig. 5: SCP iterations (left), cost convergence (right)",
        )
    )
    fig, (a, b) = rep.new_figure()
    for ws in WARMSTARTS:
        ws_t = np.array([s[f"{ws}_ws_time"] for s in cum])
        scp_t = np.array([s[f"{ws}_scp_time"] for s in cum])
        a.plot(x, ws_t, "-.", color=COLORS[ws], label=f"{LABELS[ws]} WS")
        a.plot(x, scp_t, "--", color=COLORS[ws], label=f"{LABELS[ws]} SCP")
        a.plot(x, ws_t + scp_t, "-", color=COLORS[ws], label=f"{LABELS[ws]} Tot")
    a.set_xlabel("C_CVX(t_1) > x")
    a.set_ylabel("runtime [s]")
    a.legend(fontsize=7, ncol=3)
    _plot_lines(b, x, cum, "infeasible_pct", "SCP infeasibility rate [%]")
    b.legend()
    plot_counts(b, x, cum)
    files.append(
        (
            rep.save_figure(fig, out / "fig6_runtime.png"),
            "Fig. 6: runtime split (left), SCP infeasibility rate (right)",
        )
    )
    return files
