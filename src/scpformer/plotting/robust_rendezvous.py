"""Figures of the robust rendezvous: free-drift arcs with uncertainty ellipses (robust ART
Fig. 7) and the passive-safety constraint history with and without margin (Fig. 8)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Ellipse

from scpformer.files import atomic_path
from scpformer.problems.robust_rendezvous.instance import RobustInstance
from scpformer.problems.robust_rendezvous.io import safety_record
from scpformer.problems.robust_rendezvous.safety import (
    covariance_at_tstar,
    drift_geometry,
    linear_model,
    plan_safety,
)


def _rt_ellipse(cov_rt: np.ndarray, center: np.ndarray, q: float, **kw) -> Ellipse:
    """``q``-sigma ellipse of a 2x2 (R, T) position covariance, drawn as (T, R)."""
    vals, vecs = np.linalg.eigh(cov_rt[::-1, ::-1])  # (T, R) order
    angle = np.degrees(np.arctan2(vecs[1, -1], vecs[0, -1]))
    w, h = 2.0 * q * np.sqrt(np.maximum(vals[::-1], 0.0))
    return Ellipse((center[1], center[0]), w, h, angle=angle, **kw)


def plot_drift_arcs(
    ax,
    instance: RobustInstance,
    x: np.ndarray,
    u: np.ndarray,
    every: int = 4,
    zoom: float | None = None,
):
    """Fig. 7: controlled path, free-drift arcs of every ``every``-th node, ellipses at ``t*``.

    ``zoom`` frames the axes at ``zoom`` times the approach ellipsoid around the target, where
    the arcs pass closest and the ellipses are visible; ``None`` shows the whole transfer.
    """
    model = linear_model(instance)
    geometry = drift_geometry(instance)
    ev = plan_safety(instance, x, u, "chance")
    cov_star = covariance_at_tstar(ev)
    rtn = model.rtn(x)
    ax.plot(rtn[:, 1], rtn[:, 0], "k.-", lw=1.2, ms=3, label="controlled (mean)")
    x_arcs, _, _ = geometry.drift(ev.y, jacobian=False)  # (N, S, 6) in the plan's dynamics
    arcs = np.einsum("ijrl,ijl->ijr", geometry.Psi[..., :3, :], x_arcs)  # (N, S, 3)
    switch = instance.scenario.n_ae_to_koz
    q = instance.uncertainty.q
    for i in range(0, instance.n_nodes, every):
        color = "tab:green" if i < switch else "tab:gray"
        ax.plot(arcs[i, :, 1], arcs[i, :, 0], "-", color=color, lw=0.6, alpha=0.7)
        Psi = ev.Psi_star[i]  # at the arc's worst instant t*
        cov = Psi[:2, :] @ cov_star[i] @ Psi[:2, :].T
        ax.add_patch(_rt_ellipse(cov, Psi[:3] @ ev.x_star[i], q, fc="none", ec=color, lw=0.8))
    for axes, name, style in (
        (instance.scenario.ae_semi_axes_m, "AE", "tab:green"),
        (instance.scenario.koz_semi_axes_m, "KOZ", "tab:red"),
    ):
        ax.add_patch(Ellipse((0, 0), 2 * axes[1], 2 * axes[0], fc="none", ec=style, ls="--",
                             label=name))  # fmt: skip
    ax.set_xlabel("T [m]")
    ax.set_ylabel("R [m]")
    ax.legend(loc="best", fontsize=8)
    if zoom is None:
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"free-drift arcs ({q:.2f}-sigma ellipses at t*)")
        return
    r_max, t_max = zoom * np.asarray(instance.scenario.ae_semi_axes_m[:2])
    half = max(r_max, t_max)
    ax.set_xlim(-half, half)
    ax.set_ylim(-half, half)
    ax.set_aspect("equal")
    ax.set_title(f"near the target ({zoom:g} x approach ellipsoid)")


def plot_constraint_history(ax, instance: RobustInstance, x: np.ndarray, u: np.ndarray) -> None:
    """Fig. 8: Eq. 15 with (dark) and without (light) the margin; > 0 is a violation."""
    rec = safety_record(instance, x, u)
    nodes = np.arange(instance.n_nodes)
    top = max(1.0, float(np.max(rec["eq15"])))
    ax.axhspan(0.0, top, color="tab:red", alpha=0.12, label="violation")
    ax.plot(nodes, rec["eq15_mean"], color="tab:blue", alpha=0.4, label="M*(x) (mean)")
    ax.plot(nodes, rec["eq15"], color="tab:blue", label="M*(x) + beta")
    ax.axvline(instance.scenario.n_ae_to_koz, color="k", ls=":", lw=0.8)
    ax.set_yscale("symlog", linthresh=1.0)
    ax.set_xlabel("node i")
    ax.set_ylabel("Eq. 15 left-hand side")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("passive-safety constraint (> 0 violates)")


def plot_solution(
    instance: RobustInstance, x: np.ndarray, u: np.ndarray, path: str | Path | None = None
):
    """Fig. 7 (whole transfer and near the target) and Fig. 8 side by side; saved to ``path``
    when given. Returns the figure."""
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(18, 5.5))
    plot_drift_arcs(ax1, instance, x, u)
    plot_drift_arcs(ax2, instance, x, u, every=2, zoom=2.0)
    plot_constraint_history(ax3, instance, x, u)
    fig.tight_layout()
    if path is not None:  # through a temporary file: a failed write keeps an earlier figure
        try:
            with atomic_path(path, suffix=Path(path).suffix or ".png") as tmp:
                fig.savefig(tmp, dpi=120)
        finally:
            plt.close(fig)
    return fig
