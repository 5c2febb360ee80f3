"""Figures for the ISS rendezvous problems (ART paper, Figs. 7 and 8).

:func:`plot_trajectory` draws, in one figure:

* the RTN trajectory in 3-D with the keep-out ellipsoid, the approach cone, the waypoint and
  the docking port (Fig. 7, left), impulses marked where they are applied;
* the keep-out constraint ``dr^T E_koz^T E_koz dr`` over time with its bound 1 and the
  interval after the waypoint where it does not apply (Fig. 7, right);
* the ROE histories as the three relative-orbit planes ``(a dlambda, a da)``,
  ``(a dex, a dey)``, ``(a dix, a diy)`` (Fig. 8, left);
* the maneuver profile: RTN components and norm of each impulse (Fig. 8, right).

An optional reference trajectory (e.g. the warm start) is drawn dashed, as in the paper.
The figures use an Agg canvas and never touch pyplot's global state.
"""

from __future__ import annotations

from collections.abc import Mapping
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from scpformer.files import atomic_path

__all__ = ["REQUIRED_CONSTANTS", "plot_trajectory"]

#: Keys that ``constants`` must provide (see ``scpformer.problems.rendezvous.io``).
REQUIRED_CONSTANTS = (
    "koz_semi_axes_m",
    "n_waypoint",
    "waypoint_m",
    "dock_port_m",
    "cone_vertex_m",
    "approach_axis",
    "cone_half_angle_deg",
    "period_s",
)

_DPI = 120
_COLOR = "tab:blue"
_REF_COLOR = "tab:orange"
_KOZ_COLOR = "tab:red"
_CONE_COLOR = "tab:green"


def _validate(
    t: Any, roe: Any, rtn: Any, dv: Any, constants: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"t must have shape (N+1,) with N >= 2, got shape {t.shape}")
    n = t.size - 1
    arrays = []
    for name, value, shape in (
        ("roe", roe, (n + 1, 6)),
        ("rtn", rtn, (n + 1, 6)),
        ("dv", dv, (n, 3)),
    ):
        arr = np.asarray(value, dtype=float)
        if arr.shape != shape:
            raise ValueError(f"{name} must have shape {shape} to match t, got shape {arr.shape}")
        arrays.append(arr)
    if not isinstance(constants, Mapping):
        raise ValueError(f"constants must be a mapping, got {type(constants).__name__}")
    missing = [k for k in REQUIRED_CONSTANTS if k not in constants]
    if missing:
        raise ValueError(f"constants is missing required key(s): {', '.join(missing)}")
    return t, arrays[0], arrays[1], arrays[2]


def _axes_tnr(r: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plot coordinates (T, N, R): along-track, cross-track, radial (R up)."""
    return r[..., 1], r[..., 2], r[..., 0]


def _draw_geometry(ax, constants: Mapping[str, Any]) -> None:
    rr, rt, rn = (float(v) for v in constants["koz_semi_axes_m"])
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, 37), np.linspace(0, np.pi, 19))
    koz = np.stack([rr * np.cos(u) * np.sin(v), rt * np.sin(u) * np.sin(v), rn * np.cos(v)], -1)
    ax.plot_wireframe(*_axes_tnr(koz), color=_KOZ_COLOR, alpha=0.15, linewidth=0.5)
    ax.plot([], [], color=_KOZ_COLOR, alpha=0.5, label="keep-out ellipsoid")
    apex = np.asarray(constants["cone_vertex_m"], dtype=float)
    axis = np.asarray(constants["approach_axis"], dtype=float)
    wp = np.asarray(constants["waypoint_m"], dtype=float)
    length = float(axis @ (wp - apex)) * 1.15
    gamma = np.radians(float(constants["cone_half_angle_deg"]))
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    s, phi = np.meshgrid(np.linspace(0, length, 8), np.linspace(0, 2 * np.pi, 37))
    rad = s * np.tan(gamma)
    cone = (
        apex
        + s[..., None] * axis
        + rad[..., None] * (np.cos(phi)[..., None] * e1 + np.sin(phi)[..., None] * e2)
    )
    ax.plot_surface(*_axes_tnr(cone), color=_CONE_COLOR, alpha=0.15, linewidth=0, shade=False)
    ax.plot([], [], color=_CONE_COLOR, alpha=0.5, label=f"approach cone {np.degrees(gamma):g}°")
    ax.scatter(*_axes_tnr(wp), color="black", marker="D", s=30, label="waypoint", depthshade=False)
    port = np.asarray(constants["dock_port_m"], dtype=float)
    ax.scatter(*_axes_tnr(port), color="black", marker="X", s=60, label="docking port")


def _draw_rtn(ax, rtn, dv, constants, reference) -> None:
    _draw_geometry(ax, constants)
    if reference is not None:
        ax.plot(
            *_axes_tnr(reference["rtn"]), "--", color=_REF_COLOR, lw=1.2, label=reference["label"]
        )
    ax.plot(*_axes_tnr(rtn), color=_COLOR, lw=1.6, label="trajectory")
    norms = np.linalg.norm(dv, axis=1)
    burns = norms > 1e-2 * max(norms.max(), 1e-12)
    ax.scatter(*_axes_tnr(rtn[:-1][burns]), color=_COLOR, s=14, marker="o", label="impulses")
    ax.scatter(*_axes_tnr(rtn[0]), color="black", s=30, marker="o", label="start")
    ax.set_xlabel("T [m]")
    ax.set_ylabel("N [m]")
    ax.set_zlabel("R [m]")
    span = np.ptp(np.r_[rtn[:, :3], [[0.0, 0.0, 0.0]]], axis=0)
    ax.set_box_aspect((span[1] + 1.0, span[2] + 1.0, span[0] + 1.0), zoom=1.25)
    ax.view_init(elev=22, azim=-60)
    ax.legend(loc="upper left", bbox_to_anchor=(-0.12, 1.0), fontsize=7, framealpha=0.85)
    ax.set_title("RTN trajectory (Fig. 7)")


def _draw_koz(ax, t_orb, rtn, constants, reference) -> None:
    E2 = 1.0 / np.asarray(constants["koz_semi_axes_m"], dtype=float) ** 2
    kw = int(constants["n_waypoint"])
    if reference is not None:
        ref = (reference["rtn"][:, :3] ** 2) @ E2
        ax.plot(t_orb, ref, "--", color=_REF_COLOR, lw=1.1, label=reference["label"])
    ax.plot(t_orb, (rtn[:, :3] ** 2) @ E2, color=_COLOR, lw=1.4, label="trajectory")
    ax.axhline(1.0, color=_KOZ_COLOR, ls="--", lw=1.1, label="bound (>= 1)")
    ax.axvspan(t_orb[kw], t_orb[-1], color="0.85", alpha=0.6, label="not enforced")
    ax.set_yscale("log")
    ax.set_xlabel("time [orbits]")
    ax.set_ylabel(r"$\delta r^T E_{koz}^T E_{koz} \delta r$")
    ax.set_title("Keep-out constraint (Fig. 7)")
    ax.legend(fontsize=7, loc="best")


_PLANES = (
    ((1, 0), r"$a\delta\lambda$ [m]", r"$a\delta a$ [m]"),
    ((2, 3), r"$a\delta e_x$ [m]", r"$a\delta e_y$ [m]"),
    ((4, 5), r"$a\delta i_x$ [m]", r"$a\delta i_y$ [m]"),
)


def _draw_roe(axes, roe, reference) -> None:
    for ax, ((i, j), xlabel, ylabel) in zip(axes, _PLANES, strict=True):
        if reference is not None:
            ax.plot(reference["roe"][:, i], reference["roe"][:, j], "--", color=_REF_COLOR, lw=1.1)
        ax.plot(roe[:, i], roe[:, j], color=_COLOR, lw=1.4, marker=".", ms=2.5)
        ax.scatter(roe[0, i], roe[0, j], color="black", s=20, zorder=3)
        ax.scatter(roe[-1, i], roe[-1, j], color="black", marker="X", s=40, zorder=3)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
    axes[0].set_title("ROE (Fig. 8)")


def _draw_maneuvers(ax, t_orb, dv) -> None:
    tk = t_orb[:-1]
    for c, (name, color) in enumerate(
        zip("RTN", ("tab:red", "tab:green", "tab:purple"), strict=True)
    ):
        ax.vlines(
            tk + (c - 1) * 0.002,
            0.0,
            1e3 * dv[:, c],
            color=color,
            lw=1.6,
            label=f"$\\Delta v_{name}$",
        )
    ax.plot(tk, 1e3 * np.linalg.norm(dv, axis=1), "k.", ms=3, label=r"$\|\Delta v\|_2$")
    ax.axhline(0.0, color="0.5", lw=0.8)
    ax.set_xlabel("time [orbits]")
    ax.set_ylabel(r"$\Delta v$ [mm/s]")
    ax.set_title("Maneuver profile (Fig. 8)")
    ax.legend(fontsize=7, ncol=4, loc="best")
    ax.grid(True, alpha=0.3)


def plot_trajectory(
    t: Any,
    roe: Any,
    rtn: Any,
    dv: Any,
    constants: Mapping[str, Any],
    path: str | PathLike[str] | None = None,
    title: str | None = None,
    reference: Mapping[str, Any] | None = None,
) -> Figure:
    """Plot a rendezvous trajectory as Figs. 7 and 8 of the ART paper.

    Parameters
    ----------
    t : array_like, shape (N+1,)
        Node times [s].
    roe : array_like, shape (N+1, 6)
        Scaled ROE ``a dalpha`` [m].
    rtn : array_like, shape (N+1, 6)
        Relative RTN states [m, m/s].
    dv : array_like, shape (N, 3)
        Impulses in RTN [m/s], ``dv[k]`` at ``t[k]``.
    constants : mapping
        The keys of :data:`REQUIRED_CONSTANTS` (the ``constants`` record of the .npz file).
    path : path-like, optional
        If given, the figure is saved there in the format its suffix names (dpi 120).
    title : str, optional
        Figure title.
    reference : mapping, optional
        ``{"rtn": (N+1, 6), "roe": (N+1, 6), "label": str}`` drawn dashed (e.g. warm start).

    Returns
    -------
    matplotlib.figure.Figure
        Six axes: 3-D RTN, keep-out constraint, three ROE planes, maneuver profile.

    Raises
    ------
    ValueError
        On inconsistent shapes or a missing constant.
    """
    t, roe, rtn, dv = _validate(t, roe, rtn, dv, constants)
    if reference is not None:
        reference = {
            "rtn": np.asarray(reference["rtn"], dtype=float),
            "roe": np.asarray(reference["roe"], dtype=float),
            "label": str(reference.get("label", "reference")),
        }
        if reference["rtn"].shape != rtn.shape or reference["roe"].shape != roe.shape:
            raise ValueError("reference rtn/roe must have the shapes of rtn/roe")
    t_orb = (t - t[0]) / float(constants["period_s"])
    fig = Figure(figsize=(15.0, 10.0))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(
        3,
        3,
        height_ratios=(1.5, 1.0, 0.8),
        hspace=0.38,
        wspace=0.3,
        left=0.05,
        right=0.98,
        bottom=0.06,
        top=0.93,
    )
    _draw_rtn(fig.add_subplot(grid[0, :2], projection="3d"), rtn, dv, constants, reference)
    _draw_koz(fig.add_subplot(grid[0, 2]), t_orb, rtn, constants, reference)
    _draw_roe([fig.add_subplot(grid[1, c]) for c in range(3)], roe, reference)
    _draw_maneuvers(fig.add_subplot(grid[2, :]), t_orb, dv)
    cost = 1e3 * np.linalg.norm(dv, axis=1).sum()
    fig.suptitle(title or f"ISS rendezvous: N = {t.size - 1}, cost {cost:.1f} mm/s", fontsize=13)
    if path is not None:  # through a temporary file: a failed write keeps an earlier figure
        with atomic_path(path, suffix=Path(path).suffix or ".png") as tmp:
            fig.savefig(tmp, dpi=_DPI)  # format from the suffix
    return fig
