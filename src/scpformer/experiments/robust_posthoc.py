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
        "cvx_cost": column(rows, "chance_cvx_cost"),
        "art_cost": column(rows, f"{art}_cost"),
        "cvx_ok": column(rows, "chance_cvx_converged") == 1.0,
        "art_ok": column(rows, f"{art}_converged") == 1.0,
        "cvx_iter": column(rows, "chance_cvx_iterations"),
        "art_iter": column(rows, f"{art}_iterations"),
    }


def analyse_posthoc(rows: list[dict[str, str]], frame: str, report: rep.Report, out: Path) -> None:
    """Figs. 9-10, the table with and without the check, and the paper's claims."""
    d = _chance(rows, frame)
    both = d["cvx_ok"] & d["art_ok"]
    gain = MM * (d["cvx_cost"] - d["art_cost"])  # mm/s, > 0: ART better
    checked = np.where(d["accept"], gain, 0.0)
    art_infeasible = ~d["art_ok"]
    checked_infeasible = np.where(d["accept"], ~d["art_ok"], ~d["cvx_ok"])
    both_checked = both | (~d["accept"] & d["cvx_ok"])

    def summary(values: np.ndarray, mask: np.ndarray) -> list[str]:
        v = values[mask]
        return [
            rep.fmt(float(np.mean(v))) if v.size else "n/a",
            rep.fmt(float(v.min())) if v.size else "n/a",
            rep.fmt(float(v.max())) if v.size else "n/a",
        ]

    table = [
        [
            "without the check",
            *summary(gain, both),
            rep.fmt(100.0 * float(np.mean(art_infeasible))),
            "100",
        ],
        [
            "with the check",
            *summary(checked, both_checked),
            rep.fmt(100.0 * float(np.mean(checked_infeasible))),
            rep.fmt(100.0 * float(np.mean(d["accept"]))),
        ],
    ]
    header = (
        "PS-ART-C",
        "mean gain [mm/s]",
        "min [mm/s]",
        "max [mm/s]",
        "infeasible [%]",
        "ART guesses used [%]",
    )
    report.sections.append(
        (
            "J_SCP,CVX - J_SCP,ART with and without the post hoc check",
            rep.markdown_table(header, table)
            + f"\n\nPS-CVX-C infeasible: {rep.fmt(100.0 * float(np.mean(~d['cvx_ok'])))}%.",
        )
    )
    check = AcceptanceCheck()
    C = rep.Comparison
    lo = float(checked[both_checked].min()) if both_checked.any() else math.nan
    report.comparisons += [
        C(
            quantity="acceptance region",
            paper="-1.5 <= 100 E_R <= 3.5, 0 <= E_C <= 2",
            ours=f"{check.e_r_percent[0]:g} <= 100 E_R <= {check.e_r_percent[1]:g}, "
            f"{check.e_c[0]:g} <= E_C <= {check.e_c[1]:g}",
        ),
        C(
            quantity="smallest J_SCP,CVX - J_SCP,ART with the check [mm/s]",
            paper="much closer to zero than without",
            ours=rep.fmt(lo),
            note=f"without: {summary(gain, both)[1]}",
        ),
        C(
            quantity="range of J_SCP,CVX - J_SCP,ART with the check [mm/s]",
            paper="-10 < . < 500",
            ours=f"[{rep.fmt(lo)}, {summary(checked, both_checked)[2]}]",
        ),
    ]
    report.figures += [_fig9(d, gain, both, out), _fig10(gain, checked, both, both_checked, out)]


def _fig9(
    d: dict[str, np.ndarray], gain: np.ndarray, both: np.ndarray, out: Path
) -> tuple[str, str]:
    check = AcceptanceCheck()
    fig, axes = rep.new_figure(ncols=3, width=15.0)
    saved = d["cvx_iter"] - d["art_iter"]
    panels = (
        (None, "population"),
        (gain, "J_SCP,CVX - J_SCP,ART [mm/s]"),
        (saved, "iterations saved by ART"),
    )
    for ax, (values, title) in zip(axes, panels, strict=True):
        if values is None:
            ax.scatter(d["E_R"], d["E_C"], s=10, color="tab:blue")
        else:
            m = both & np.isfinite(values)
            scale = max(float(np.max(np.abs(values[m]))), 1e-12) if m.any() else 1.0
            sc = ax.scatter(
                d["E_R"][m],
                d["E_C"][m],
                c=values[m],
                cmap="coolwarm",
                vmin=-scale,
                vmax=scale,
                s=14,
            )
            fig.colorbar(sc, ax=ax)
        (r0, r1), (c0, c1) = check.e_r_percent, check.e_c
        ax.add_patch(_box(r0, c0, r1 - r0, c1 - c0))
        ax.set_xlabel("100 E_R")
        ax.set_ylabel("E_C")
        ax.set_title(title)
    return (
        rep.save_figure(fig, out / "fig9_posthoc.png"),
        "Fig. 9: ART guesses in the (100 E_R, E_C) plane; box: acceptance region",
    )


def _box(x: float, y: float, w: float, h: float) -> Any:
    from matplotlib.patches import Rectangle

    return Rectangle((x, y), w, h, fill=False, edgecolor="black", ls="--")


def _fig10(
    gain: np.ndarray, checked: np.ndarray, both: np.ndarray, both_checked: np.ndarray, out: Path
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
        rep.save_figure(fig, out / "fig10_posthoc_histogram.png"),
        "Fig. 10: the gain of PS-ART-C over PS-CVX-C without and with the check",
    )


# ======================================================================================
# robust-trajectory
# ======================================================================================
def show_trajectory(
    rows: list[dict[str, str]],
    frame: str,
    solver: Any,
    tasks: list[Any],
    report: rep.Report,
    out: Path,
) -> None:
    """Figs. 7-8 for the instance with the largest gain of PS-ART-C over PS-CVX-C."""
    d = _chance(rows, frame)
    both = d["cvx_ok"] & d["art_ok"]
    gain = np.where(both, d["cvx_cost"] - d["art_cost"], -np.inf)
    if both.any():
        best = int(np.argmax(gain))
        why = f"the largest gain of PS-ART-C over PS-CVX-C among {len(rows)} test instances"
    elif (d["cvx_ok"] | d["art_ok"]).any():
        best = int(np.flatnonzero(d["cvx_ok"] | d["art_ok"])[0])
        why = f"no instance of {len(rows)} where both converged; the first where one did"
    else:
        report.sections.append(("Instance", "No instance where PS-CVX-C or PS-ART-C converged."))
        return
    index = int(rows[best][KEY])
    theta = next(t.theta for t in tasks if t.index == index)
    solver.warm_up()
    instance = solver.instance(theta)
    guesses = solver.guesses(instance, "chance")
    art_guess = guesses[f"art_{frame}"]
    solutions = {
        name: solver.scp(instance, "chance", guesses[src])
        for name, src in (("PS-CVX-C", "cvx"), ("PS-ART-C", f"art_{frame}"))
    }
    plans = {"CVX": guesses["cvx"].trajectory, "ART": art_guess.trajectory}
    for name, solution in solutions.items():  # a solve that failed keeps an earlier stage
        plans[name] = solution.trajectory if solution.converged else None
    costs = {
        k: (float(np.linalg.norm(z.u, axis=1).sum()) if z is not None else math.nan)
        for k, z in plans.items()
    }
    report.sections.append(
        (
            "Instance",
            f"dataset sample {index}: {why}; the ART guess was "
            f"{'accepted' if art_guess.record.accepted else 'rejected'} by the check.",
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
    from scpformer.plotting.robust_rendezvous import plot_constraint_history
    from scpformer.problems.robust_rendezvous.montecarlo import MonteCarloConfig, monte_carlo

    fig, axes = rep.new_figure(ncols=3, width=16.0, height=4.5)
    rows = []
    for ax, name in zip(axes[:2], ("PS-CVX-C", "PS-ART-C"), strict=True):
        z = plans[name]
        if z is None:
            continue
        plot_constraint_history(ax, instance, z.x, z.u)
        ax.set_title(f"{name}: Eq. 15 (> 0 violates)")
        mc = monte_carlo(
            instance, z.x, z.u, MonteCarloConfig(n_samples=MONTE_CARLO_SAMPLES, propagator="linear")
        )
        axes[2].plot(mc.nodes, mc.p_dense, ".-", label=name)
        rows.append(
            [
                name,
                rep.fmt(float(mc.p_dense.max())),
                rep.fmt(mc.delta),
                "yes" if mc.passes(dense=True) else "no",
            ]
        )
    axes[2].axhline(instance.uncertainty.delta, color="black", ls="--", label="Delta")
    axes[2].set_xlabel("node i")
    axes[2].set_ylabel("P(enter the ellipsoid during the drift)")
    axes[2].legend()
    report.sections.append(
        (
            f"Monte Carlo ({MONTE_CARLO_SAMPLES} draws per node, linear propagator)",
            rep.markdown_table(
                ("solution", "max violation probability", "Delta", "within Delta (binomial test)"),
                rows,
            ),
        )
    )
    return (
        rep.save_figure(fig, out / "fig8_constraints.png"),
        "Fig. 8: Eq. 15 with and without the margin; Monte Carlo violation probability",
    )
