"""Figures for the 6-DoF free-final-time powered descent guidance problem.

Two figures are provided:

* :func:`plot_trajectory` -- a 3-D view of the trajectory with the thrust plume at
  every node and the glideslope cone, next to time histories of the quantities that
  carry path constraints (thrust magnitude, gimbal angle, tilt angle, angular rate,
  mass) and the speed, in the style of Fig. 3 of the T-SCvx 6-DoF paper.
* :func:`plot_history` -- SCvx convergence history (cost, penalty, trust radius,
  virtual control norm) against the iteration number.

Conventions (nondimensional units ``U_L``, ``U_T``, ``U_M``):

* inertial frame ``I``: ``e1`` = Up (opposite gravity), ``e2`` = East, ``e3`` = North,
  origin at the landing site;
* state ``x = [r_I (3), v_I (3), q_{B<-I} (4, scalar first), omega_B (3, rad/U_T), m]``;
* control ``u = T_B`` (3), thrust in the body frame, body ``x`` axis = thrust axis.

The figures are built on :class:`matplotlib.figure.Figure` with an Agg canvas, so they
never touch pyplot's global state or need a display.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import FormatStrFormatter
from mpl_toolkits.mplot3d.art3d import Line3DCollection

from scpformer.dynamics import quaternion as quat
from scpformer.files import atomic_path

__all__ = ["REQUIRED_CONSTANTS", "plot_history", "plot_trajectory"]

#: Keys that ``constants`` must provide for :func:`plot_trajectory`.
REQUIRED_CONSTANTS = (
    "T_min",
    "T_max",
    "delta_max_deg",
    "theta_max_deg",
    "omega_max_deg",
    "m_dry",
    "gamma_gs_deg",
)

#: Keys that every row given to :func:`plot_history` must provide.
HISTORY_KEYS = ("iteration", "cost", "penalty", "trust_radius", "virtual_control_norm")

_N_STATE = 14
_N_CONTROL = 3
_DPI = 120

_TRAJ_COLOR = "tab:blue"
_PLUME_COLOR = "tab:red"
_BOUND_STYLE = {"color": "red", "linestyle": "--", "linewidth": 1.2}


# --------------------------------------------------------------------------- helpers


def _validate(t: Any, x: Any, u: Any, constants: Any) -> tuple[np.ndarray, ...]:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.shape[0] < 2:
        raise ValueError(f"t must have shape (N,) with N >= 2 node times, got shape {t.shape}")
    n = t.shape[0]
    x = np.asarray(x, dtype=float)
    if x.shape != (n, _N_STATE):
        raise ValueError(
            f"x must have shape (N, {_N_STATE}) = ({n}, {_N_STATE}) to match t, got shape {x.shape}"
        )
    u = np.asarray(u, dtype=float)
    if u.shape != (n, _N_CONTROL):
        raise ValueError(
            f"u must have shape (N, {_N_CONTROL}) = ({n}, {_N_CONTROL}) to match t, "
            f"got shape {u.shape}"
        )
    if not isinstance(constants, Mapping):
        raise ValueError(f"constants must be a mapping, got {type(constants).__name__}")
    missing = [k for k in REQUIRED_CONSTANTS if k not in constants]
    if missing:
        raise ValueError(f"constants is missing required key(s): {', '.join(missing)}")
    return t, x, u


def _new_figure(figsize: tuple[float, float], layout: str | None = "constrained") -> Figure:
    fig = Figure(figsize=figsize, layout=layout)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: str | PathLike[str] | None) -> None:
    """Write ``fig`` to ``path`` (format from the suffix) through a temporary file, so that a
    failed write (full disk) leaves an earlier figure at ``path`` untouched."""
    if path is not None:
        with atomic_path(path, suffix=Path(path).suffix or ".png") as tmp:
            fig.savefig(tmp, dpi=_DPI)


def _bound(ax, value: float, label: str | None) -> None:
    ax.axhline(value, label=label if label is not None else "_nolegend_", **_BOUND_STYLE)


# --------------------------------------------------------------------------- trajectory


def _draw_3d(ax, x: np.ndarray, u: np.ndarray, constants: Mapping[str, Any]) -> None:
    # Plot coordinates: (East, North, Up) = (r2, r3, r1).
    up, east, north = x[:, 0], x[:, 1], x[:, 2]

    # Thrust plumes: segments from each node opposite the inertial thrust direction,
    # with length proportional to the thrust magnitude (T_max -> 12 % of the trajectory
    # extent).
    thrust_i = quat.rotate(quat.normalize(x[:, 6:10]), u)
    extent = max(float(np.max(np.ptp(x[:, 0:3], axis=0))), float(np.max(np.abs(x[:, 0:3]))))
    t_ref = float(constants["T_max"])
    if not t_ref > 0.0:
        t_ref = max(float(np.max(np.linalg.norm(u, axis=1))), 1e-12)
    tail = x[:, 0:3] - (0.12 * max(extent, 1e-9) / t_ref) * thrust_i
    t_up, t_east, t_north = tail[:, 0], tail[:, 1], tail[:, 2]

    # View box centred horizontally on the landing site (so the cone fits inside), with
    # equal scaling on all three axes; the horizontal extent is widened for steep
    # descents so the box never gets taller than 0.75 of its width.
    h_data = max(float(np.max(np.abs(np.r_[east, north, t_east, t_north]))), 1e-9)
    z_lo = min(0.0, float(np.min(up)), float(np.min(t_up)))
    z_data = max(float(max(np.max(up), np.max(t_up))) - z_lo, 1e-9)
    half = 1.05 * max(h_data, z_data / 1.5)
    z_span = 1.04 * max(z_data, 0.5 * half)
    z_hi = z_lo + z_span
    ax.set_xlim(-half, half)
    ax.set_ylim(-half, half)
    ax.set_zlim(z_lo, z_hi)
    ax.set_box_aspect((2 * half, 2 * half, z_span), zoom=1.1)

    # Glideslope cone: Up >= tan(gamma) * horizontal distance, apex at the landing site.
    gamma = np.deg2rad(float(constants["gamma_gs_deg"]))
    if 0.0 < gamma < np.pi / 2:
        tan_g = np.tan(gamma)
        rho_max = min(half, z_hi / tan_g)
        rho, phi = np.meshgrid(np.linspace(0.0, rho_max, 12), np.linspace(0.0, 2 * np.pi, 49))
        ax.plot_surface(
            rho * np.cos(phi),
            rho * np.sin(phi),
            tan_g * rho,
            color="tab:green",
            alpha=0.07,
            linewidth=0,
            shade=False,
        )
        ang = np.linspace(0.0, 2 * np.pi, 121)
        ax.plot(
            rho_max * np.cos(ang),
            rho_max * np.sin(ang),
            np.full_like(ang, tan_g * rho_max),
            color="tab:green",
            alpha=0.4,
            linewidth=0.8,
            label=rf"glideslope cone, $\gamma_{{gs}}$ = {np.rad2deg(gamma):g}°",
        )

    # Ground track on the surface (Up = 0).
    ax.plot(
        east,
        north,
        np.zeros_like(up),
        color="0.5",
        linestyle=":",
        linewidth=1.0,
        label="ground track",
    )

    # Trajectory and plumes.
    ax.plot(
        east,
        north,
        up,
        color=_TRAJ_COLOR,
        linewidth=1.8,
        marker="o",
        markersize=2.5,
        label="trajectory",
        zorder=3,
    )
    start = np.column_stack([east, north, up])
    end = np.column_stack([t_east, t_north, t_up])
    ax.add_collection3d(
        Line3DCollection(
            np.stack([start, end], axis=1),
            colors=_PLUME_COLOR,
            linewidths=1.3,
            label="thrust plume ($-T_I$)",
        )
    )

    # Start and landing site.
    ax.scatter(
        [east[0]],
        [north[0]],
        [up[0]],
        color="black",
        marker="o",
        s=28,
        depthshade=False,
        label="start",
    )
    ax.scatter(
        [0.0], [0.0], [0.0], color="black", marker="X", s=70, depthshade=False, label="landing site"
    )

    ax.set_xlabel(r"East [$U_L$]", labelpad=8)
    ax.set_ylabel(r"North [$U_L$]", labelpad=8)
    ax.set_zlabel(r"Up [$U_L$]", labelpad=6)
    ax.view_init(elev=20, azim=-58)
    ax.legend(loc="upper left", bbox_to_anchor=(0.03, 0.97), fontsize=9, framealpha=0.85)


def plot_trajectory(
    t: Any,
    x: Any,
    u: Any,
    constants: Mapping[str, Any],
    path: str | PathLike[str] | None = None,
    title: str | None = None,
) -> Figure:
    """Plot a 6-DoF powered descent trajectory and its constrained time histories.

    Parameters
    ----------
    t : array_like, shape (N,)
        Node times [``U_T``].
    x : array_like, shape (N, 14)
        States ``[r_I, v_I, q_{B<-I} (scalar first), omega_B (rad/U_T), m]`` with
        inertial axes Up, East, North.
    u : array_like, shape (N, 3)
        Body-frame thrust vectors; the body ``x`` axis is the thrust axis.
    constants : mapping
        Must contain ``T_min``, ``T_max``, ``delta_max_deg``, ``theta_max_deg``,
        ``omega_max_deg``, ``m_dry`` and ``gamma_gs_deg``.
    path : path-like, optional
        If given, the figure is saved there in the format its suffix names (dpi 120).
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
        Seven axes: the 3-D trajectory followed by six time-history axes (thrust,
        gimbal, tilt, angular rate, mass, speed).

    Raises
    ------
    ValueError
        If ``t``, ``x`` or ``u`` have inconsistent shapes or ``constants`` lacks a key.
    """
    t, x, u = _validate(t, x, u, constants)

    thrust = np.linalg.norm(u, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        gimbal = np.rad2deg(np.arccos(np.clip(u[:, 0] / thrust, -1.0, 1.0)))
    gimbal[thrust == 0.0] = np.nan
    q = x[:, 6:10] / np.linalg.norm(x[:, 6:10], axis=1, keepdims=True).clip(min=1e-300)
    tilt = np.rad2deg(quat.tilt_angle(q))
    rate = np.rad2deg(np.linalg.norm(x[:, 10:13], axis=1))
    mass = x[:, 13]
    speed = np.linalg.norm(x[:, 3:6], axis=1)

    # Fixed layout: constrained/tight layout do not account for the labels of a 3-D
    # axis, which then spill over the neighbouring panels.
    fig = _new_figure((15.0, 7.6), layout=None)
    ax3d = fig.add_axes((-0.025, 0.0, 0.56, 0.93), projection="3d")
    _draw_3d(ax3d, x, u, constants)
    grid = fig.add_gridspec(
        3, 2, left=0.63, right=0.99, bottom=0.075, top=0.9, wspace=0.33, hspace=0.3
    )
    axes = grid.subplots(sharex=True)
    style = {"color": _TRAJ_COLOR, "marker": ".", "markersize": 4, "linewidth": 1.4}

    theta_max = float(constants["theta_max_deg"])
    # the panels row by row: series, bounds (value, legend label), y label, title
    panels = (
        (thrust, [(constants["T_max"], r"$T_{min}$, $T_{max}$"), (constants["T_min"], None)],
         r"$\|T_B\|$ [$U_M U_L/U_T^2$]", "Thrust magnitude"),
        (gimbal, [(constants["delta_max_deg"], r"$\delta_{max}$")], r"$\delta$ [deg]",
         "Gimbal angle"),
        (tilt, [(theta_max, r"$\theta_{max}$")] if theta_max < 180.0 else [],
         r"$\theta$ [deg]", "Tilt angle"),
        (rate, [(constants["omega_max_deg"], r"$\omega_{max}$")],
         r"$\|\omega_B\|$ [deg/$U_T$]", "Angular rate"),
        (mass, [(constants["m_dry"], r"$m_{dry}$")], r"$m$ [$U_M$]", "Mass"),
        (speed, [], r"$\|v_I\|$ [$U_L/U_T$]", "Speed"),
    )  # fmt: skip
    for ax, (series, bounds, ylabel, name) in zip(axes.flat, panels, strict=True):
        ax.plot(t, series, **style)
        for value, label in bounds:
            _bound(ax, float(value), label)
        ax.set_ylabel(ylabel)
        ax.set_title(name)

    for ax in axes.flat:
        ax.grid(True, alpha=0.3)
        ax.margins(x=0.02)
        lo, hi = ax.get_ylim()
        if ax is not axes[2, 0]:
            # Non-negative quantities: anchor at zero so small values are not magnified,
            # with a little room below so a curve lying on zero stays visible.
            lo = 0.0
        span = hi - lo
        ax.set_ylim(lo - (0.04 * span if ax is not axes[2, 0] else 0.0), hi + 0.06 * span)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize=8, framealpha=0.85)
    for ax in axes[-1]:
        ax.set_xlabel(r"time [$U_T$]")

    tf = t[-1] - t[0]
    suptitle = (
        title
        if title is not None
        else (
            f"6-DoF powered descent: $t_f$ = {tf:.3g} $U_T$, "
            f"$m(t_f)$ = {mass[-1]:.3g} $U_M$, N = {t.shape[0]}"
        )
    )
    fig.suptitle(suptitle, fontsize=13, y=0.985)

    _save(fig, path)
    return fig


# --------------------------------------------------------------------------- history


def _column(rows: Sequence[Mapping[str, Any]], key: str) -> np.ndarray:
    return np.array([np.nan if r[key] is None else float(r[key]) for r in rows], dtype=float)


def _history_markers(
    ax, it: np.ndarray, vals: np.ndarray, rejected: np.ndarray, corrected: np.ndarray,
    polished: np.ndarray,
) -> None:  # fmt: skip
    """Markers of :func:`plot_history`: filled circles for accepted conic solves, hollow for
    rejected candidates, diamonds for least-change corrections, squares for accepted steps
    that were then polished (labelled when present)."""
    kinds = (
        (~rejected & ~corrected & ~polished, "o", _TRAJ_COLOR, "accepted"),
        (rejected, "o", "white", "rejected"),
        (corrected & ~rejected, "D", _TRAJ_COLOR, "least-change correction"),
        (polished & ~rejected & ~corrected, "s", _TRAJ_COLOR, "accepted, then polished"),
    )
    for mask, marker, face, label in kinds:
        if mask.any():
            ax.plot(it[mask], vals[mask], linestyle="none", marker=marker, markersize=4.5,
                    markerfacecolor=face, markeredgecolor=_TRAJ_COLOR, label=label)  # fmt: skip


def _autoscale_log(ax, values: np.ndarray) -> None:
    """Log-y when all finite values are positive, symlog if some are, else linear."""
    finite = values[np.isfinite(values)]
    positive = finite[finite > 0]
    if finite.size and positive.size == finite.size:
        ax.set_yscale("log")
        if np.max(positive) < 10.0 * np.min(positive):
            # Less than a decade: matplotlib labels minor ticks as "6x10^-1"; use plain
            # numbers instead.
            ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
            ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    elif positive.size:
        ax.set_yscale("symlog", linthresh=float(np.min(positive)))


def plot_history(
    history_rows: Sequence[Mapping[str, Any]],
    path: str | PathLike[str] | None = None,
    restart_after: int | None = None,
) -> Figure:
    """Plot an SCvx convergence history.

    Parameters
    ----------
    history_rows : sequence of mappings
        One mapping per iteration with keys ``iteration``, ``cost``, ``penalty``,
        ``trust_radius`` and ``virtual_control_norm``; ``None`` values are skipped. Optional
        keys (those of :meth:`~scpformer.scp.solution.IterationRecord.summary`): rows with
        ``accepted`` false are drawn as hollow markers (a rejected candidate), rows with
        ``solver_status == "least_change"`` as diamonds (a correction without a conic solve),
        rows with ``polished`` true as squares (an accepted step, then polished onto the
        nonlinear flow: its cost and penalty are the polished iterate's).
    path : path-like, optional
        If given, the figure is saved there in the format its suffix names (dpi 120).
    restart_after : int, optional
        Iterations of a first run that was restarted (``Solution.extras["restart"]["after"]``):
        a dashed vertical line marks where the restart begins.

    Returns
    -------
    matplotlib.figure.Figure
        A 2x2 grid: cost (linear, it is typically ``-m(t_f)``), and penalty, trust
        radius and virtual-control norm on log-y axes (symlog if zeros occur).

    Raises
    ------
    ValueError
        If ``history_rows`` is empty or a row lacks a required key.
    """
    rows = list(history_rows)
    if not rows:
        raise ValueError("history_rows must contain at least one row")
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ValueError(f"history_rows[{i}] must be a mapping, got {type(row).__name__}")
        missing = [k for k in HISTORY_KEYS if k not in row]
        if missing:
            raise ValueError(f"history_rows[{i}] is missing key(s): {', '.join(missing)}")

    it = _column(rows, "iteration")
    fig = _new_figure((10.0, 6.4))
    axes = fig.subplots(2, 2, sharex=True)
    panels = (
        ("cost", "Cost", "cost", False),
        ("penalty", "Penalty", "penalty", True),
        ("trust_radius", "Trust-region radius", "radius", True),
        ("virtual_control_norm", "Virtual control", r"$\|\nu\|$", True),
    )
    rejected = np.array([row.get("accepted", True) is False for row in rows])
    corrected = np.array([row.get("solver_status") == "least_change" for row in rows])
    polished = np.array([row.get("polished") is True for row in rows])
    for ax, (key, title, ylabel, log) in zip(axes.flat, panels, strict=True):
        vals = _column(rows, key)
        ax.plot(it, vals, color=_TRAJ_COLOR, linewidth=1.4)
        _history_markers(ax, it, vals, rejected, corrected, polished)
        if restart_after is not None:
            ax.axvline(restart_after + 0.5, color="0.4", linestyle="--", linewidth=1.0,
                       label="restart")  # fmt: skip
        if log:
            _autoscale_log(ax, vals)
        ax.set_title(title)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="major", alpha=0.35)
        ax.grid(True, which="minor", alpha=0.12)
    for ax in axes[-1]:
        ax.set_xlabel("iteration")
        ax.xaxis.get_major_locator().set_params(integer=True)
    if rejected.any() or corrected.any() or polished.any() or restart_after is not None:
        axes.flat[0].legend(loc="best", fontsize=8)
    solves = len(rows) - int(corrected.sum())
    fig.suptitle(f"SCvx convergence ({len(rows)} iterations, {solves} conic solves)", fontsize=13)

    _save(fig, path)
    return fig
