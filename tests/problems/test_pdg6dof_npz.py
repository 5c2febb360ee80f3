"""The .npz output is enough to check a trajectory without the package (slow: one solve)."""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from scpformer.cli.main import main

pytestmark = pytest.mark.slow

REQUIRED = (
    "g_I",
    "J_B",
    "r_T_B",
    "r_cp_B",
    "alpha_mdot",
    "beta_mdot",
    "rho_SA_CA",
    "T_min",
    "T_max",
    "m_dry",
    "delta_max_deg",
    "omega_max_deg",
    "theta_max_deg",
    "gamma_gs_deg",
    "r_f",
    "v_f",
)


def independent_rhs(c):
    """Eq. 4 written from scratch with scipy's rotations (scalar-last there)."""
    J = np.array(c["J_B"])
    g, r_T, r_cp = (np.array(c[k]) for k in ("g_I", "r_T_B", "r_cp_B"))

    def rhs(t, x, u):
        q = x[6:10]
        C = Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()  # C_{I<-B}
        w, m = x[10:13], x[13]
        v_B = C.T @ x[3:6]
        aero = -0.5 * c["rho_SA_CA"] * np.linalg.norm(v_B) * v_B
        qdot = 0.5 * np.concatenate([[-w @ q[1:]], q[0] * w + np.cross(q[1:], w)])
        wdot = np.linalg.solve(J, np.cross(r_T, u) + np.cross(r_cp, aero) - np.cross(w, J @ w))
        mdot = -c["alpha_mdot"] * np.linalg.norm(u) - c["beta_mdot"]
        return np.concatenate([x[3:6], C @ (u + aero) / m + g, qdot, wdot, [mdot]])

    return rhs


def test_npz_trajectory_replays_through_an_independent_model(tmp_path):
    out = tmp_path / "sol.npz"
    assert main(["solve", "pdg6dof", "--out", str(out)]) == 0
    data = np.load(out)
    c = json.loads(str(data["constants"]))
    assert all(key in c for key in REQUIRED)
    assert np.array(c["J_B"]).shape == (3, 3)
    t, x, u = data["t"], data["x"], data["u"]
    assert x.shape == (50, 14) and u.shape == (50, 3) and t[-1] == pytest.approx(data["tf"])
    assert str(data["status"]) == "converged"
    rhs = independent_rhs(c)
    state = x[0]
    for k in range(len(t) - 1):
        dt = t[k + 1] - t[k]
        sol = solve_ivp(
            lambda s, y, k=k, dt=dt: rhs(s, y, u[k] + (s / dt) * (u[k + 1] - u[k])),
            (0.0, dt),
            state,
            rtol=1e-10,
            atol=1e-10,
        )
        state = sol.y[:, -1]
    np.testing.assert_allclose(state[0:3], c["r_f"], atol=5e-3)
    np.testing.assert_allclose(state[3:6], c["v_f"], atol=5e-3)
    thrust = np.linalg.norm(u, axis=1)
    assert np.all(thrust <= c["T_max"] + 1e-6) and np.all(thrust >= c["T_min"] - 1e-4)
    gimbal = np.degrees(np.arccos(np.clip(u[:, 0] / thrust, -1, 1)))
    assert gimbal.max() <= c["delta_max_deg"] + 1e-3
    assert x[:, 13].min() >= c["m_dry"] - 1e-6
