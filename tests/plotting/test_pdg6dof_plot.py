"""Tests for the 6-DoF powered descent figures."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
from matplotlib.figure import Figure

from scpformer.plotting.pdg6dof import plot_history, plot_trajectory

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

CONSTANTS = {
    "T_min": 0.3,
    "T_max": 5.0,
    "delta_max_deg": 20.0,
    "theta_max_deg": 90.0,
    "omega_max_deg": 90.0,
    "m_dry": 2.0,
    "gamma_gs_deg": 20.0,
}


def synthetic_trajectory(n: int = 30):
    """Straight-line descent from r = (4, 4, 0) [Up, East, North] to the origin in 6 U_T."""
    t = np.linspace(0.0, 6.0, n)
    s = t / t[-1]
    r0 = np.array([4.0, 4.0, 0.0])
    r = (1.0 - s)[:, None] * r0
    v = np.tile(-r0 / t[-1], (n, 1))
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    w = np.zeros((n, 3))
    u = np.tile([3.0, 0.0, 0.0], (n, 1))
    alpha = 1.0 / 30.0  # 1 / (I_sp g0) with I_sp = 30 U_T, g0 = 1
    m = 3.0 - alpha * 3.0 * t
    x = np.column_stack([r, v, q, w, m])
    return t, x, u


def test_plot_trajectory_axes_and_png(tmp_path):
    t, x, u = synthetic_trajectory()
    out = tmp_path / "traj.png"
    fig = plot_trajectory(t, x, u, CONSTANTS, path=out, title="synthetic descent")
    assert isinstance(fig, Figure)
    axes = fig.get_axes()
    assert len(axes) == 7  # one 3-D axis + six time histories
    assert sum(ax.name == "3d" for ax in axes) == 1
    data = out.read_bytes()
    assert data.startswith(PNG_MAGIC)
    assert len(data) > 10_000


def test_plot_trajectory_without_path_and_unbounded_tilt():
    t, x, u = synthetic_trajectory(5)
    constants = {**CONSTANTS, "theta_max_deg": 180.0}
    fig = plot_trajectory(t, x, u, constants)
    assert len(fig.get_axes()) == 7
    tilt_ax = next(ax for ax in fig.get_axes() if ax.get_title() == "Tilt angle")
    assert tilt_ax.get_legend() is None  # no theta_max bound line drawn


@pytest.mark.parametrize(
    ("which", "bad_shape"),
    [("t", (30, 1)), ("x", (30, 13)), ("x", (29, 14)), ("u", (30, 4)), ("u", (3, 30))],
)
def test_plot_trajectory_rejects_wrong_shape(which, bad_shape):
    args = dict(zip(("t", "x", "u"), synthetic_trajectory(30), strict=True))
    args[which] = np.zeros(bad_shape)
    with pytest.raises(ValueError, match=rf"^{which} must have shape"):
        plot_trajectory(args["t"], args["x"], args["u"], CONSTANTS)


def test_plot_trajectory_rejects_missing_constant():
    t, x, u = synthetic_trajectory(5)
    constants = {k: v for k, v in CONSTANTS.items() if k != "m_dry"}
    with pytest.raises(ValueError, match=r"constants.*m_dry"):
        plot_trajectory(t, x, u, constants)


def test_plot_history(tmp_path):
    rows = [
        {
            "iteration": k,
            "cost": -3.0 + 0.5 * 0.5**k,
            "penalty": 10.0 * 0.1**k,
            "trust_radius": 2.0 * 2.0 ** (-(k % 3)),
            "virtual_control_norm": 5.0 * 0.2**k if k < 7 else 0.0,
        }
        for k in range(1, 9)
    ]
    out = tmp_path / "history.png"
    fig = plot_history(rows, path=out)
    assert len(fig.get_axes()) == 4
    assert out.read_bytes().startswith(PNG_MAGIC)
    with pytest.raises(ValueError, match="history_rows"):
        plot_history([])
    with pytest.raises(ValueError, match="penalty"):
        plot_history(
            [{"iteration": 1, "cost": 1.0, "trust_radius": 1.0, "virtual_control_norm": 1.0}]
        )


@pytest.mark.parametrize(
    "suffix, magic", [(".png", PNG_MAGIC), (".pdf", b"%PDF"), (".svg", b"<?xml")]
)
def test_the_figure_is_written_in_the_format_its_suffix_names(tmp_path, suffix, magic):
    t, x, u = synthetic_trajectory()
    out = tmp_path / f"traj{suffix}"
    plot_trajectory(t, x, u, CONSTANTS, path=out)
    assert out.read_bytes().startswith(magic)


def test_the_history_plot_marks_rejected_steps_and_least_change_corrections():
    rows = [
        {"iteration": k, "cost": -k, "penalty": 1.0 / k, "trust_radius": 1.0,
         "virtual_control_norm": 1e-9, "accepted": k != 2,
         "solver_status": "least_change" if k == 3 else "optimal", "polished": k == 5}
        for k in range(1, 6)
    ]  # fmt: skip
    fig = plot_history(rows, restart_after=2)
    cost_axis = fig.get_axes()[0]
    labels = [text.get_text() for text in cost_axis.get_legend().get_texts()]
    assert labels == [
        "accepted", "rejected", "least-change correction", "accepted, then polished", "restart"
    ]  # fmt: skip
    marked = {line.get_label(): list(line.get_xdata()) for line in cost_axis.get_lines()}
    assert marked["restart"] == [2.5, 2.5]  # between the runs' iterations 2 and 3
    assert marked["rejected"] == [2] and marked["least-change correction"] == [3]
    assert marked["accepted"] == [1, 4] and marked["accepted, then polished"] == [5]
    assert "5 iterations, 4 conic solves" in fig._suptitle.get_text()
