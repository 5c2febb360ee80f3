"""How long can EmbersArc's draws stay inside the 6-DoF path constraints?

For each draw of ``benchmarks/pdg6dof_embersarc.py`` (the same instance and constants as its
``scpformer solve pdg6dof`` call) this solves, with IPOPT through casadi,

    max  t_f   s.t.  the 6-DoF dynamics from x_0,  every path constraint at every node,
                     t_f in [tf_min, tf_max],  and NO terminal condition.

A landing with final time t_f stays inside the path constraints until t_f, so the maximum
bounds the final time of every landing of the draw. A short bound (the vehicle cannot brake
before it leaves the glideslope cone), with a landing search that fails at such short final
times, says the draw has no landing. IPOPT is a local solver: the answer, the same from every
start that converges, is strong evidence, not a certificate of infeasibility.

The transcription is the solver's own (``n_sub`` RK4 steps per interval, thrust linear in
time between the nodes, constraints at the nodes) written in casadi, and its dynamics are
checked against :func:`scpformer.dynamics.powered_descent.dynamics` at random points before
any solve. The constraints are those of :func:`scpformer.problems.pdg6dof.constraints
.constraint_values` in smooth squared forms (glideslope ``tan^2(gamma) |r_h|^2 <= r_up^2``
with ``r_up >= 0``; gimbal ``T_2^2 + T_3^2 <= tan^2(delta) T_1^2`` with ``T_1 >= 0``; thrust,
rate and tilt bounds on squared norms). The result of every start is verified by propagating
its thrust from ``x_0`` with DOP853 (:func:`scpformer.problems.pdg6dof.problem.propagate`)
and evaluating the constraints there.

Measured (seed 0, single runs; docs/studies/embersarc-scenario.md): with ``--n-nodes 30``
draw 0 stays inside for the whole 60 s from all 4 starts, draw 1 for 5.98 s and draw 2 for
4.53 s from the 2 shorter starts (IPOPT did not converge from the 2 longer ones); with
``--n-nodes 80`` draw 0 again 60 s and draw 1 5.98 s (2 starts). At that point the vehicle
is on the glideslope cone beyond the pad, still moving away from it. A verified violation of
about 1e-2 on draw 0 at 30 nodes is the coarse grid over 60 s (3e-5 at 80 nodes).

Requires casadi (``pip install casadi``); not a dependency of scpformer.

Usage: python benchmarks/pdg6dof_viability.py [--draws 3] [--seed 0] [--n-nodes 30]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from pathlib import Path

import numpy as np

# run as a script, this folder is on the import path: the EmbersArc benchmark's draws
from pdg6dof_embersarc import draw_initial_state, solve_arguments

from scpformer.cli.main import build_parser
from scpformer.cli.pdg6dof import config_from_args, instance_from_args
from scpformer.dynamics import powered_descent as pd
from scpformer.problems.pdg6dof import constraints as con
from scpformer.problems.pdg6dof.guess import cubic_profile_trajectory
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.problem import PDGSolverConfig, propagate
from scpformer.scp.solution import Trajectory

START_TIMES = (0.9, 1.5, 2.3, 3.5)  # initial final-time guesses, U_T (about 6-24 s)
SOLVED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def embersarc_problem(state: dict[str, np.ndarray]) -> tuple[PDGInstance, PDGSolverConfig]:
    """The instance and configuration that ``pdg6dof_embersarc.py`` solves for ``state``."""
    with tempfile.TemporaryDirectory() as folder:
        argv = solve_arguments(state, Path(folder) / "draw.json")
        args = build_parser().parse_args(argv)
        return instance_from_args(args), config_from_args(args)


def casadi_dynamics(instance: PDGInstance):  # -> casadi.Function
    """``f(x, u)`` of Eq. 4 (no aerodynamics: EmbersArc's scenario has none) in casadi."""
    import casadi as ca

    c = instance.constants
    if c.rho_SA_CA != 0.0:
        raise ValueError("the casadi dynamics leave out aerodynamics; rho_SA_CA must be 0")
    x, u = ca.SX.sym("x", 14), ca.SX.sym("u", 3)
    v, q, w, m = x[3:6], x[6:10], x[10:13], x[13]
    skew = ca.vertcat(
        ca.horzcat(0, -q[3], q[2]), ca.horzcat(q[3], 0, -q[1]), ca.horzcat(-q[2], q[1], 0)
    )
    dcm = ca.DM.eye(3) + 2 * q[0] * skew + 2 * skew @ skew  # C_{I<-B}
    q_dot = 0.5 * ca.vertcat(
        -q[1] * w[0] - q[2] * w[1] - q[3] * w[2],
        q[0] * w[0] + q[2] * w[2] - q[3] * w[1],
        q[0] * w[1] + q[3] * w[0] - q[1] * w[2],
        q[0] * w[2] + q[1] * w[1] - q[2] * w[0],
    )
    inertia = ca.DM(c.J_B_diag)
    torque = ca.cross(ca.DM(c.r_T_B), u) - ca.cross(w, inertia * w)
    model = c.model()
    m_dot = -model.alpha_mdot * ca.norm_2(u) - model.beta_mdot
    rates = ca.vertcat(v, dcm @ u / m + ca.DM(c.g_I), q_dot, torque / inertia, m_dot)
    return ca.Function("f", [x, u], [rates])


def check_dynamics(instance: PDGInstance, f, rng: np.random.Generator) -> float:
    """Largest |casadi - scpformer| of ``f`` over 20 random states and thrusts."""
    model = instance.constants.model()
    worst = 0.0
    for _ in range(20):
        x = rng.normal(size=14)
        x[6:10] /= np.linalg.norm(x[6:10])
        x[13] = abs(x[13]) + 1.0
        u = 3.0 * rng.normal(size=3)
        ours = pd.dynamics(model, x[None], u[None])[0]
        worst = max(worst, float(np.abs(np.asarray(f(x, u)).ravel() - ours).max()))
    return worst


def interval_flow(f, n_sub: int):  # -> casadi.Function
    """``F(x_k, u_k, u_{k+1}, h)``: ``n_sub`` RK4 steps over one interval, thrust linear."""
    import casadi as ca

    x = xk = ca.SX.sym("xk", 14)
    u_a, u_b, h = ca.SX.sym("ua", 3), ca.SX.sym("ub", 3), ca.SX.sym("h")
    dt = h / n_sub

    def thrust(s: float):
        return u_a + s * (u_b - u_a)

    for j in range(n_sub):
        s0, s1, s2 = j / n_sub, (j + 0.5) / n_sub, (j + 1.0) / n_sub
        k1 = f(x, thrust(s0))
        k2 = f(x + 0.5 * dt * k1, thrust(s1))
        k3 = f(x + 0.5 * dt * k2, thrust(s1))
        k4 = f(x + dt * k3, thrust(s2))
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return ca.Function("F", [xk, u_a, u_b, h], [x])


def longest_stay(
    instance: PDGInstance, config: PDGSolverConfig, f, guess: Trajectory
) -> tuple[str, Trajectory]:
    """IPOPT's answer to the problem of the module docstring from ``guess``."""
    import casadi as ca

    c, n = instance.constants, config.n_nodes
    opti = ca.Opti()
    X, U, tf = opti.variable(14, n), opti.variable(3, n), opti.variable()
    flow = interval_flow(f, config.n_sub).map(n - 1)
    opti.subject_to(
        X[:, 1:] == flow(X[:, :-1], U[:, :-1], U[:, 1:], ca.repmat(tf / (n - 1), 1, n - 1))
    )
    opti.subject_to(X[:, 0] == instance.x0)
    opti.subject_to(opti.bounded(c.tf_min, tf, c.tf_max))
    opti.subject_to(X[13, :] >= c.m_dry)
    opti.subject_to(X[0, :] >= 0)
    opti.subject_to(instance.tan_gamma_gs**2 * (X[1, :] ** 2 + X[2, :] ** 2) <= X[0, :] ** 2)
    opti.subject_to(X[8, :] ** 2 + X[9, :] ** 2 <= instance.tilt_bound**2)
    opti.subject_to(ca.sum1(X[10:13, :] ** 2) <= math.radians(c.omega_max_deg) ** 2)
    opti.subject_to(opti.bounded(c.T_min**2, ca.sum1(U**2), c.T_max**2))
    opti.subject_to(U[0, :] >= 0)
    tan_gimbal = math.tan(math.radians(c.delta_max_deg))
    opti.subject_to(U[1, :] ** 2 + U[2, :] ** 2 <= tan_gimbal**2 * U[0, :] ** 2)
    opti.minimize(-tf)
    opti.set_initial(X, guess.x.T)
    opti.set_initial(U, guess.u.T)
    opti.set_initial(tf, float(guess.p[0]))
    options = {"max_iter": 1500, "tol": 1e-9, "print_level": 0, "mu_strategy": "adaptive"}
    opti.solver("ipopt", {"print_time": False}, options)
    try:
        solution = opti.solve()
    except RuntimeError:
        solution = opti.debug  # the last iterate; its status says what went wrong
    status = str(opti.stats()["return_status"])
    x, u = np.asarray(solution.value(X)).T, np.asarray(solution.value(U)).T
    return status, Trajectory(x=x, u=u, p=np.array([float(solution.value(tf))]))


def verified_violation(instance: PDGInstance, z: Trajectory) -> float:
    """Largest constraint value (> 0: violated) and node mismatch after DOP853 propagation
    (``inf`` when the propagation itself fails)."""
    try:
        propagated = propagate(instance, z)
    except RuntimeError:
        return math.inf
    values = con.constraint_values(instance, propagated, z.u)
    return max(float(values.max()), float(np.abs(propagated - z.x).max()))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-nodes", type=int, default=30)
    args = parser.parse_args()
    try:
        import casadi  # noqa: F401
    except ModuleNotFoundError:
        parser.error("this benchmark needs casadi (pip install casadi)")
    rng = np.random.default_rng(args.seed)
    check_rng = np.random.default_rng(12345)  # not ``rng``: the draws must stay EmbersArc's
    for draw in range(args.draws):
        state = draw_initial_state(rng)
        instance, config = embersarc_problem(state)
        config = PDGSolverConfig(n_nodes=args.n_nodes, n_sub=config.n_sub, fix_roll=True)
        f = casadi_dynamics(instance)
        unit_time = math.sqrt(float(np.linalg.norm(state["r"])) / 9.81)
        print(
            f"--- draw {draw}: dynamics vs scpformer {check_dynamics(instance, f, check_rng):.1e}"
        )
        for t_guess in START_TIMES:
            guess = cubic_profile_trajectory(instance, args.n_nodes, t_guess)
            status, z = longest_stay(instance, config, f, guess)
            start = f"start t_f {t_guess * unit_time:5.1f} s: {status:28s}"
            if status not in SOLVED:
                print(f"{start} no answer (IPOPT did not converge)", flush=True)
                continue
            print(
                f"{start} longest stay {float(z.p[0]) * unit_time:6.2f} s, verified "
                f"violation {verified_violation(instance, z):.1e}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
