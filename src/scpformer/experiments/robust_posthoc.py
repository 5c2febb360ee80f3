"""Analyses of ``robust-posthoc`` (robust paper Figs. 9-10) and ``robust-trajectory`` (Figs. 7-8).

Both read the chance-constrained rows of :mod:`scpformer.experiments.robust_studies`
(PS-CVX-C and PS-ART-C per instance).

``robust-posthoc``: ART's guesses start SCvx* without the acceptance check; each row records
``E_R`` and ``E_C`` (Eq. 8) and whether the check would accept. Fig. 9: the population in the
``(100 E_R, E_C)`` plane and, over it, the suboptimality improvement
``J_SCP,CVX - J_SCP,ART`` and the iterations saved; Fig. 10: the histogram of the improvement
with the check (a rejected guess falls back to CVX: improvement 0) beside the one without.

``robust-trajectory``: the instance with the largest ART gain is solved again in this process;
Fig. 7 shows its warm starts and solutions with the free-drift arcs and their 3-sigma
ellipses, Fig. 8 the left-hand side of Eq. 15 with and without the margin, and the Monte Carlo
probability of entering the safety ellipsoid during each node's free drift.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.experiments import report as rep
from scpformer.experiments.runner import KEY, column
from scpformer.warmstart import AcceptanceCheck

MM = 1e3
MONTE_CARLO_SAMPLES = 200  # draws per node (linear propagator: the design model)


def _chance(rows: list[dict[str, str]], frame: str) -> dict[str, np.ndarray]:
    art = f"chance_art_{frame}"
    return {
        "E_R": 100.0 * column(rows, f"{art}_E_R"),
        "E_C": column(rows, f"{art}_E_C"),
        "accept": column(rows, f"{art}_would_accept") == 1.0,
        "j_cvx": column(rows, "j_cvx"),
        "cvx_cost": column(rows, "chance_cvx_cost"),
        "art_cost": column(rows, f"{art}_cost"),
        "cvx_ok": column(rows, "chance_cvx_converged") == 1.0,
        "art_ok": column(rows, f"{art}_converged") == 1.0,
        "cvx_iter": column(rows, "chance_cvx_iterations"),
        "art_iter": column(rows, f"{art}_iterations"),
    }


def analyse_posthoc(
    rows: list[dict[str, str]], frames: tuple[str, ...], report: rep.Report, out: Path
) -> None:
    """Figs. 9-10, the table with and without the check, and the paper's claims, per model."""
    check = AcceptanceCheck()
    report.comparisons.append(
        rep.Comparison(
            quantity="acceptance region",
            paper="-1.5 <= 100 E_R <= 3.5, 0 <= E_C <= 2",
            ours=f"{check.e_r_percent[0]:g} <= 100 E_R <= {check.e_r_percent[1]:g}, "
            f"{check.e_c[0]:g} <= E_C <= {check.e_c[1]:g}",
        )
    )
    for frame in frames:
        _posthoc_one(rows, frame, report, out)


def _mean(values: np.ndarray, mask: np.ndarray) -> float:
    return float(np.mean(values[mask])) if mask.any() else math.nan


def _posthoc_one(rows: list[dict[str, str]], frame: str, report: rep.Report, out: Path) -> None:
    d = _chance(rows, frame)
    name = f"PS-ART-C ({frame.upper()})"
    both = d["cvx_ok"] & d["art_ok"]
    gain = MM * (d["cvx_cost"] - d["art_cost"])  # mm/s, > 0: ART better
    checked = np.where(d["accept"], gain, 0.0)
    checked_ok = np.where(d["accept"], d["art_ok"], d["cvx_ok"])
    both_checked = d["cvx_ok"] & checked_ok

    def summary(values: np.ndarray, mask: np.ndarray) -> list[str]:
        v = values[mask]
        if not v.size:
            return ["n/a"] * 3
        return [rep.fmt(float(np.mean(v))), rep.fmt(float(v.min())), rep.fmt(float(v.max()))]

    table = [
        [
            "without the check",
            *summary(gain, both),
            rep.fmt(100.0 * float(np.mean(~d["art_ok"]))),
            "100",
        ],
        [
            "with the check",
            *summary(checked, both_checked),
            rep.fmt(100.0 * float(np.mean(~checked_ok))),
            rep.fmt(100.0 * float(np.mean(d["accept"]))),
        ],
    ]
    header = (
        name,
        "mean gain [mm/s]",
        "min [mm/s]",
        "max [mm/s]",
        "infeasible [%]",
        "ART guesses used [%]",
    )
    report.sections.append(
        (
            f"{name}: J_SCP,CVX - J_SCP,ART with and without the post hoc check",
            rep.markdown_table(header, table)
            + f"\n\nPS-CVX-C infeasible: {rep.fmt(100.0 * float(np.mean(~d['cvx_ok'])))}%; "
            f"instances: {len(rows)}.",
        )
    )
    finite = np.isfinite(d["E_R"]) & np.isfinite(d["E_C"])
    inside, outside = both & d["accept"], both & ~d["accept"]
    C = rep.Comparison
    report.comparisons += [
        C(
            quantity=f"{name}: guesses with E_C = C_ART(t_1) = 0 [%]",
            paper="the majority",
            ours=rep.fmt(100.0 * _mean(d["E_C"] == 0.0, finite)),
        ),
        C(
            quantity=f"{name}: guesses cheaper than CVX, E_R < 0 [%]",
            paper="most",
            ours=rep.fmt(100.0 * _mean(d["E_R"] < 0.0, finite)),
        ),
        C(
            quantity=f"{name}: mean J_SCP,CVX - J_SCP,ART inside vs outside the region [mm/s]",
            paper="larger at small E_R, E_C",
            ours=f"{rep.fmt(_mean(gain, inside))} vs {rep.fmt(_mean(gain, outside))}",
            note=f"n = {int(inside.sum())} vs {int(outside.sum())} (both converged)",
        ),
        C(
            quantity=f"{name}: smallest J_SCP,CVX - J_SCP,ART, with vs without the check [mm/s]",
            paper="closer to 0 with the check (Fig. 10 vs Fig. 6a)",
            ours=f"{summary(checked, both_checked)[1]} vs {summary(gain, both)[1]}",
        ),
        C(
            quantity=f"{name} without the check: converged where PS-CVX-C did not, and the reverse",
            paper="ART lowers the infeasibility rate (Fig. 6)",
            ours=f"{int((d['art_ok'] & ~d['cvx_ok']).sum())} vs "
            f"{int((~d['art_ok'] & d['cvx_ok']).sum())}",
            note=f"of {len(rows)} instances",
        ),
        C(
            quantity=f"{name}: infeasibility with the check, without, PS-CVX-C [%]",
            paper="n/a (not reported)",
            ours=" / ".join(
                rep.fmt(100.0 * float(np.mean(~ok)))
                for ok in (checked_ok, d["art_ok"], d["cvx_ok"])
            ),
        ),
    ]
    report.figures += [
        _fig9(d, frame, out),
        _fig10(gain, checked, both, both_checked, frame, out),
    ]


def tile_edges(e_r: np.ndarray, e_c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Tile edges of Fig. 9 that grow away from the acceptance region.

    ``100 E_R``: the region's bounds, then widths doubling outwards until the data are
    covered; ``E_C`` (an integer count): tiles ``{0}, {1}, {2}, {3, 4}, {5..8}, ...``.
    """
    r_lo, r_hi = AcceptanceCheck().e_r_percent
    r = e_r[np.isfinite(e_r)]
    c = e_c[np.isfinite(e_c)]
    lo, hi = (float(r.min()), float(r.max())) if r.size else (r_lo, r_hi)
    width = r_hi - r_lo
    upper, lower = [r_lo, r_hi], [r_lo]
    while upper[-1] < hi:
        width *= 2.0
        upper.append(upper[-1] + width)
    width = r_hi - r_lo
    while lower[-1] > lo:
        width *= 2.0
        lower.append(lower[-1] - width)
    c_edges = [-0.5, 0.5, 1.5, 2.5]
    top = float(c.max()) if c.size else 0.0
    while c_edges[-1] < top:
        c_edges.append(2.0 * c_edges[-1] - 0.5)
    return np.array(lower[:0:-1] + upper), np.array(c_edges)


def tile_means(
    e_r: np.ndarray, e_c: np.ndarray, values: np.ndarray, edges: tuple[np.ndarray, np.ndarray]
) -> np.ndarray:
    """Mean of ``values`` per ``(E_C, E_R)`` tile (NaN where a tile holds no instance)."""
    m = np.isfinite(e_r) & np.isfinite(e_c) & np.isfinite(values)
    sums, _, _ = np.histogram2d(e_c[m], e_r[m], bins=(edges[1], edges[0]), weights=values[m])
    counts, _, _ = np.histogram2d(e_c[m], e_r[m], bins=(edges[1], edges[0]))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / np.where(counts > 0, counts, 1.0), np.nan)


def _fig9(d: dict[str, np.ndarray], frame: str, out: Path) -> tuple[str, str]:
    """Population, suboptimality improvement and iterations saved, averaged over the tiles.

    The improvement is absolute (mm/s): the ratio to ``J_SCP,CVX - J_CVX`` explodes in tiles
    where PS-CVX-C ends at the lower bound, which is most of ours.
    """
    both = d["cvx_ok"] & d["art_ok"]
    edges = tile_edges(d["E_R"], d["E_C"])
    population = np.histogram2d(
        d["E_C"][np.isfinite(d["E_C"])],
        d["E_R"][np.isfinite(d["E_C"])],
        bins=(edges[1], edges[0]),
    )[0]
    counts = np.where(population > 0, population, np.nan)
    nan = np.full_like(d["E_R"], np.nan)
    gain = tile_means(
        d["E_R"], d["E_C"], np.where(both, MM * (d["cvx_cost"] - d["art_cost"]), nan), edges
    )
    saved = tile_means(
        d["E_R"], d["E_C"], np.where(both, d["cvx_iter"] - d["art_iter"], nan), edges
    )
    from matplotlib import colormaps

    fig, axes = rep.new_figure(ncols=3, width=16.0, height=4.5)
    panels = (
        (counts, "(a) population", "viridis", False),
        (gain, "(b) suboptimality improvement J_SCP,CVX - J_SCP,ART [mm/s]", "coolwarm", True),
        (saved, "(c) SCP iterations saved by ART", "coolwarm", True),
    )
    check = AcceptanceCheck()
    (r0, r1), (c0, c1) = check.e_r_percent, check.e_c
    box = (np.searchsorted(edges[0], [r0, r1]), np.searchsorted(edges[1], [c0 - 0.5, c1 + 0.5]))
    for ax, (grid, title, cmap_name, centred) in zip(axes, panels, strict=True):
        cmap = colormaps[cmap_name].with_extremes(bad="lightgray")
        finite = grid[np.isfinite(grid)]
        scale = float(np.max(np.abs(finite))) if finite.size else 0.0
        limits = {"vmin": -(scale or 1.0), "vmax": scale or 1.0} if centred else {}
        mesh = ax.pcolormesh(np.ma.masked_invalid(grid), cmap=cmap, **limits)  # tile indices
        fig.colorbar(mesh, ax=ax)
        (i0, i1), (j0, j1) = box
        ax.add_patch(_box(i0, j0, i1 - i0, j1 - j0))
        ax.set_xticks(np.arange(edges[0].size), [f"{v:g}" for v in edges[0]], fontsize=7)
        ax.set_yticks(np.arange(edges[1].size), [f"{v:g}" for v in edges[1]], fontsize=7)
        ax.set_xlabel("100 E_R (tile edges)")
        ax.set_ylabel("E_C (tile edges)")
        ax.set_title(title, fontsize=9)
    return (
        rep.save_figure(fig, out / f"fig9_posthoc_{frame}.png"),
        f"Fig. 9 ({frame.upper()} model): ART guesses over (100 E_R, E_C) tiles (gray: no "
        "instance; red: ART better); dashed box: acceptance region",
    )


def _box(x: float, y: float, w: float, h: float) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((x, y), w, h, fill=False, edgecolor="black", ls="--")


def _fig10(
    gain: np.ndarray,
    checked: np.ndarray,
    both: np.ndarray,
    both_checked: np.ndarray,
    frame: str,
    out: Path,
) -> tuple[str, str]:
    fig, axes = rep.new_figure(ncols=2)
    for ax, values, mask, title in (
        (axes[0], gain, both, "without the check"),
        (axes[1], checked, both_checked, "with the check"),
    ):
        v = values[mask]
        if v.size:
            ax.hist(v, bins=20, color="tab:blue")
            for x in (v.min(), v.max()):
                ax.axvline(x, color="red", ls=":")
        ax.set_xlabel("J_SCP,CVX - J_SCP,ART [mm/s]")
        ax.set_ylabel("instances")
        ax.set_title(title)
    return (
        rep.save_figure(fig, out / f"fig10_posthoc_histogram_{frame}.png"),
        f"Fig. 10 ({frame.upper()} model): the gain of PS-ART-C over PS-CVX-C without and with "
        "the check",
    )


# ======================================================================================
# robust-trajectory
# ======================================================================================
def best_instance(rows: list[dict[str, str]], frames: tuple[str, ...]) -> tuple[int, str, str]:
    """Row position and model frame of the largest ``J_SCP,CVX - J_SCP,ART`` (chance mode),
    and why it was chosen (``(-1, "", why)`` when no SCvx* run converged)."""
    best, best_frame, best_gain = -1, "", -math.inf
    for frame in frames:
        d = _chance(rows, frame)
        gain = np.where(d["cvx_ok"] & d["art_ok"], d["cvx_cost"] - d["art_cost"], -np.inf)
        if gain.size and float(gain.max()) > best_gain:
            best, best_frame, best_gain = int(np.argmax(gain)), frame, float(gain.max())
    if best >= 0:
        return (
            best,
            best_frame,
            (
                f"the largest gain of PS-ART-C over PS-CVX-C among {len(rows)} test instances and "
                f"the {len(frames)} model(s)"
            ),
        )
    for frame in frames:
        d = _chance(rows, frame)
        ok = np.flatnonzero(d["cvx_ok"] | d["art_ok"])
        if ok.size:
            return (
                int(ok[0]),
                frame,
                (f"no instance of {len(rows)} where both converged; the first where one did"),
            )
    return -1, "", "no instance where PS-CVX-C or PS-ART-C converged"


def show_trajectory(
    rows: list[dict[str, str]],
    frames: tuple[str, ...],
    solver: Any,
    tasks: list[Any],
    report: rep.Report,
    out: Path,
) -> None:
    """Figs. 7-8 for the instance with the largest gain of PS-ART-C over PS-CVX-C.

    The SCvx* runs start from the guesses the study used (with the check); the "ART" curves
    show the model's own guess even when the check rejected it.
    """
    position, frame, why = best_instance(rows, frames)
    if position < 0:
        report.sections.append(("Instance", why + "."))
        return
    index = int(rows[position][KEY])
    theta = next(t.theta for t in tasks if t.index == index)
    solver.warm_up()
    instance = solver.instance(theta)
    guesses = solver.guesses(instance, "chance")
    source = f"art_{frame}"
    raw = copy.copy(solver)
    raw.check = False
    art_guess = raw.guesses(instance, "chance")[source] if solver.check else guesses[source]
    solutions = {
        name: solver.scp(instance, "chance", guesses[src])
        for name, src in (("PS-CVX-C", "cvx"), ("PS-ART-C", source))
    }
    plans = {"CVX": guesses["cvx"].trajectory, "ART": art_guess.trajectory}
    for name, solution in solutions.items():  # a solve that failed keeps an earlier stage
        plans[name] = solution.trajectory if solution.converged else None
    costs = {
        k: (float(np.linalg.norm(z.u, axis=1).sum()) if z is not None else math.nan)
        for k, z in plans.items()
    }
    accepted = rows[position].get(f"chance_{source}_would_accept") == "True"
    started = "ART's own guess" if not solver.check or accepted else "CVX (fallback)"
    report.sections.append(
        (
            "Instance",
            f"dataset sample {index}, {frame.upper()} model: {why}; the post hoc check would "
            f"{'accept' if accepted else 'reject'} ART's guess; PS-ART-C started from {started}.",
        )
    )
    paper = {"CVX": "4.7916", "PS-CVX-C": "5.2892", "ART": "4.7895", "PS-ART-C": "4.7917"}
    report.comparisons += [
        rep.Comparison(
            quantity=f"Delta v_tot of {k} [m/s]",
            paper=f"{v} (their instance)",
            ours=rep.fmt(costs[k], 5),
            note="our instance with the largest gain",
        )
        for k, v in paper.items()
    ]
    report.figures += [_fig7(instance, plans, out), _fig8(instance, plans, report, out)]


def _fig7(instance: Any, plans: dict[str, Any], out: Path) -> tuple[str, str]:
    from scpformer.plotting.robust_rendezvous import plot_drift_arcs
    from scpformer.problems.robust_rendezvous.safety import linear_model

    model = linear_model(instance)
    fig, axes = rep.new_figure(ncols=3, width=16.0, height=5.0)
    for name, z in plans.items():
        if z is not None:
            rtn = model.rtn(z.x)
            axes[0].plot(rtn[:, 1], rtn[:, 0], "--" if name in ("CVX", "ART") else "-", label=name)
    axes[0].set_xlabel("T [m]")
    axes[0].set_ylabel("R [m]")
    axes[0].legend()
    axes[0].set_title("warm starts (dashed) and solutions")
    for ax, name in zip(axes[1:], ("PS-ART-C", "PS-CVX-C"), strict=True):
        z = plans[name]
        if z is not None:
            plot_drift_arcs(ax, instance, z.x, z.u, every=2, zoom=2.0)
        ax.set_title(f"{name}: free-drift arcs, 3-sigma ellipses")
    return (
        rep.save_figure(fig, out / "fig7_trajectory.png"),
        "Fig. 7: warm starts and solutions; drift arcs near the target",
    )


def _fig8(instance: Any, plans: dict[str, Any], report: rep.Report, out: Path) -> tuple[str, str]:
    """Eq. 15 of the two warm starts and the two solutions; Monte Carlo of the solutions."""
    from scpformer.plotting.robust_rendezvous import plot_constraint_history
    from scpformer.problems.robust_rendezvous.io import safety_record
    from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig, monte_carlo

    fig, grid = rep.new_figure(ncols=3, nrows=2, width=16.0, height=8.0)
    layout = {"CVX": grid[0, 0], "PS-CVX-C": grid[0, 1], "ART": grid[1, 0], "PS-ART-C": grid[1, 1]}
    eq15, mc_rows = [], []
    for name, ax in layout.items():
        z = plans[name]
        if z is None:
            ax.set_title(f"{name}: did not converge")
            continue
        plot_constraint_history(ax, instance, z.x, z.u)
        ax.set_title(f"{name}: Eq. 15 (> 0 violates)")
        rec = safety_record(instance, z.x, z.u)
        eq15.append(
            [name, rep.fmt(float(np.max(rec["eq15_mean"]))), rep.fmt(float(np.max(rec["eq15"])))]
        )
        if name.startswith("PS-"):
            mc = monte_carlo(
                instance,
                z.x,
                z.u,
                MonteCarloConfig(n_samples=MONTE_CARLO_SAMPLES, propagator="linear"),
            )
            grid[0, 2].plot(mc.nodes, mc.p_dense, ".-", label=name)
            mc_rows.append([name, rep.fmt(float(mc.p_dense.max())), rep.fmt(mc.delta),
                            "yes" if mc.passes(dense=True) else "no"])  # fmt: skip
    paper = {"CVX": "> 0 (violates)", "ART": "<= 0 (passively safe)"}
    report.comparisons += [
        rep.Comparison(
            quantity=f"{name}: largest Eq. 15 left-hand side with the 3-sigma margin",
            paper=paper.get(name, "<= 0"),
            ours=with_margin,
            note="SCvx* accepts rows up to its tolerance eps_feas = 1e-3",
        )
        for name, _, with_margin in eq15
    ]
    grid[0, 2].axhline(instance.uncertainty.delta, color="black", ls="--", label="Delta")
    grid[0, 2].set_xlabel("node i")
    grid[0, 2].set_ylabel("P(enter the ellipsoid during the drift)")
    grid[0, 2].legend()
    grid[1, 2].set_axis_off()
    report.sections += [
        (
            "Fig. 8: the largest left-hand side of Eq. 15 (> 0 violates)",
            rep.markdown_table(("trajectory", "without the margin", "with the margin"), eq15)
            + "\n\nThe paper: the CVX warm start violates, ART's guess and both solutions "
            "satisfy Eq. 15 with the margin.",
        ),
        (
            f"Monte Carlo ({MONTE_CARLO_SAMPLES} draws per node, linear propagator)",
            rep.markdown_table(
                ("solution", "max violation probability", "Delta", "within Delta (binomial test)"),
                mc_rows,
            ),
        ),
    ]
    return (
        rep.save_figure(fig, out / "fig8_constraints.png"),
        "Fig. 8: Eq. 15 with (dark) and without (light) the margin for the warm starts (left) "
        "and the solutions (middle); Monte Carlo violation probability of the solutions",
    )
