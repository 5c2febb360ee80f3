"""The restart policy of a cold SCvx run that creeps (:func:`solve_with_restart`), and
:func:`concatenated`, one solution of two runs in sequence."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from scpformer.problems.pdg6dof.adapter import PDGProblem
from scpformer.problems.pdg6dof.guess import cubic_profile_trajectory
from scpformer.scp.scvx import SCvxParameters, solve_scvx, stalled
from scpformer.scp.solution import Solution, Status, Trajectory
from scpformer.validation import check_positive, check_trajectory

RESTART_TF_FACTOR = 2.0  # final time of the restart's guess, times the first run's
RESTART_DECREASE = 0.2  # the first run stops for a restart when its penalty falls less than this
RESTART_MIN_BUDGET = 10  # least solves left for a restart to be tried
RESTART_DRY_MARGIN = 0.01  # stalled with m_f below m_dry + this (m0 - m_dry): out of propellant


def checked_guess(guess: Any, default: Trajectory) -> Trajectory:
    """``guess`` after :func:`check_trajectory` against the default start, with a positive
    final time ``p[0] = t_f`` (a nonpositive one would reach the conic solver as a bound)."""
    guess = check_trajectory("guess", guess, default)
    check_positive("guess.p[0] (the final time t_f)", guess.p[0])
    return guess


def solve_with_restart(
    problem: PDGProblem, guess: Trajectory, eta_init: float | None = None
) -> Solution:
    """SCvx from the default guess, restarted once with a longer final time if it creeps.

    The cubic profile's final time is that of the translational fuel optimum; an instance
    whose attitude dynamics need much longer (e.g. EmbersArc's draw 0 of
    ``benchmarks/pdg6dof_embersarc.py``: 2.36 U_T where the cubic says 1.04) either stalls at
    an infeasible stationary point or creeps towards a feasible one: SCvx lengthens ``t_f`` by
    0.5-1.5% per iteration while the penalty falls by a few percent (draw 8: from 0.17 to 0.07
    over 70 solves; with ``t_f`` fixed at 1.1, 1.3, 1.5 and 1.8 U_T draw 0 stalls with
    penalties 0.26, 0.23, 0.16 and 0.10).

    The first run therefore applies the stall test of
    :class:`~scpformer.scp.scvx.SCvxParameters` with ``stall_decrease`` raised to
    ``RESTART_DECREASE``: a run whose penalty, above ``stall_penalty``, falls by less than 20%
    over ``stall_window`` accepted iterations stops, and is restarted from the cubic profile
    flown in ``RESTART_TF_FACTOR`` times its final time, with the solves it has left and the
    stall test as configured. A run that stops out of propellant (final mass within
    ``RESTART_DRY_MARGIN`` of the propellant above ``m_dry``) is returned ``STALLED``: a
    longer flight burns more, and of 107 such runs on instances of ``generate pdg6dof``'s
    distribution none converged when continued. With fewer than ``RESTART_MIN_BUDGET`` solves
    left, a run that has not stalled by the configured test continues from its last iterate
    instead. The result counts the solves and time of both runs, keeps both histories and
    records the restart in ``extras["restart"]``.

    Measured (README, "Restarting a creeping run"): on the ten draws of
    ``pdg6dof_embersarc.py --draws 10 --seed 0`` the eight that converge took 403 conic solves
    in all when only a 2% stall restarted a run, from 1.5 times its final time, and 253 with
    this rule; over seeds 0-2 (30 draws) 21 -> 24 converge. The bench's nominal instances
    (seeds 0 and 1) never trigger it.
    """
    params = problem.config.scvx
    first = solve_scvx(problem, guess, _first_run_params(params), eta_init=eta_init)
    if first.status is not Status.STALLED:
        return first
    instance, c = problem.instance, problem.instance.constants
    penalties = [r.penalty for r in first.history if r.accepted]
    if first.trajectory.x[-1, 13] <= c.m_dry + RESTART_DRY_MARGIN * (instance.m0 - c.m_dry):
        return _out_of_propellant(first, params.stall_window, penalties)
    budget = params.iter_max - first.iterations
    if budget < RESTART_MIN_BUDGET:
        return _continued(problem, first, penalties, budget, eta_init)
    tf = min(RESTART_TF_FACTOR * float(first.trajectory.p[0]), c.tf_max)
    restart_guess = cubic_profile_trajectory(instance, problem.config.n_nodes, tf)
    second = solve_scvx(problem, restart_guess, replace(params, iter_max=budget), eta_init)
    return _joined(first, second, tf)


def _continued(
    problem: PDGProblem,
    first: Solution,
    penalties: list[float],
    budget: int,
    eta_init: float | None,
) -> Solution:
    """A first run stopped with too few solves left for a restart: returned as it is when the
    configured stall test holds, else continued from its last iterate under that test (which
    sees the first run's accepted ``penalties``) with the ``budget`` left."""
    params = problem.config.scvx
    if stalled(params, penalties):
        return first
    if budget < 1:  # stopped by the looser test on its last solve
        message = f"no convergence in {first.iterations} iterations (slow progress)"
        return replace(first, status=Status.MAX_ITERATIONS, message=message)
    rest = solve_scvx(
        problem, first.trajectory, replace(params, iter_max=budget), eta_init,
        prior_penalties=penalties,
    )  # fmt: skip
    return _joined(first, rest, None)


def _out_of_propellant(first: Solution, window: int, penalties: list[float]) -> Solution:
    """``first`` as a run stalled out of propellant (no restart: a longer flight burns more)."""
    message = (
        f"stalled out of propellant after {first.iterations} iterations: the final mass is at "
        f"the dry mass and the penalty fell only from {penalties[-1 - window]:.3g} to "
        f"{penalties[-1]:.3g} in the last {window} accepted iterations (the instance likely "
        "lacks the propellant to land)"
    )
    return replace(first, message=message)


def _first_run_params(params: SCvxParameters) -> SCvxParameters:
    """``params`` with the restart's looser stall test (unchanged when the test is off)."""
    if params.stall_window == 0 or params.stall_decrease >= RESTART_DECREASE:
        return params
    return replace(params, stall_decrease=RESTART_DECREASE)


def concatenated(first: Solution, second: Solution) -> Solution:
    """``second`` after ``first`` as one path: both histories (the second's iterations
    numbered on), their iteration counts and wall times summed; the rest is ``second``'s."""
    offset = first.iterations
    shifted = (replace(r, iteration=r.iteration + offset) for r in second.history)
    timing = first.timing
    if timing is not None and second.timing is not None:
        timing = replace(
            second.timing,
            total=timing.total + second.timing.total,
            discretization=timing.discretization + second.timing.discretization,
            solver=timing.solver + second.timing.solver,
        )
    return replace(
        second,
        iterations=offset + second.iterations,
        history=[*first.history, *shifted],
        timing=timing,
    )


def _joined(first: Solution, second: Solution, tf_guess: float | None) -> Solution:
    """One solution of a stopped run and its restart (the restart's result, both histories);
    ``tf_guess`` is the restart guess's final time, None for a run continued from the first
    run's last iterate."""
    offset = first.iterations
    restart = {"after": offset, "tf_guess": tf_guess, "first_message": first.message}
    message = second.message
    if second.status is not Status.CONVERGED:
        how = "continued" if tf_guess is None else f"restarted with t_f = {tf_guess:.3g}"
        message = f"{how} after {offset} solves; then {message}"
    joined = concatenated(first, second)
    return replace(joined, message=message, extras={**second.extras, "restart": restart})
