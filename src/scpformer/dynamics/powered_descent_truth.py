"""The 6-DoF truth propagation: Eq. 4 under first-order-hold thrust, by a compiled DOP853.

The nonlinear check of every 6-DoF solution
(:func:`scpformer.problems.pdg6dof.problem.propagate`) integrates Eq. 4 with the thrust
``u_k + t slope`` of each interval (:func:`foh_rates`, on the independently written
:func:`scpformer.dynamics.powered_descent.scalar_rates`). The integrator is DOP853
(Hairer, Norsett & Wanner, *Solving ODEs I*, Sec. II.10) with the same method, step-size
control and dense output as ``scipy.integrate.DOP853`` (its coefficient tables, read from
scipy, its error norm, safety factor 0.9, step factors 0.2-10 and initial-step heuristic),
as a compiled loop: scipy's integrator spends about 10 us of Python per stage, a hundred
times the right-hand side itself (a verification took about 10 ms, now about 1.4 ms). A test
holds the two together step for step.

The right-hand side is called as a global, not passed in: numba does not cache functions
that take a compiled function as an argument, and compiling the integrator costs about 6 s
per process without the on-disk cache.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.integrate._ivp import dop853_coefficients as coefficients

from scpformer.dynamics.powered_descent import scalar_rates
from scpformer.jit import compiled

Array = NDArray[np.float64]

N_STAGES = coefficients.N_STAGES  # 12
A = np.ascontiguousarray(coefficients.A[:N_STAGES, :N_STAGES])
B = np.ascontiguousarray(coefficients.B)
C = np.ascontiguousarray(coefficients.C[:N_STAGES])
E3 = np.ascontiguousarray(coefficients.E3)
E5 = np.ascontiguousarray(coefficients.E5)
D = np.ascontiguousarray(coefficients.D)
A_EXTRA = np.ascontiguousarray(coefficients.A[N_STAGES + 1 :])
C_EXTRA = np.ascontiguousarray(coefficients.C[N_STAGES + 1 :])
N_EXTENDED = coefficients.N_STAGES_EXTENDED  # 16: the stages plus those of the dense output
SAFETY, MIN_FACTOR, MAX_FACTOR = 0.9, 0.2, 10.0
ERROR_EXPONENT = -1.0 / 8.0  # -1 / (error estimator order + 1)
TOO_SMALL_STEP = -1.0  # returned instead of the next step size when a step fails


@compiled
def integrate(
    params: Array, y0: Array, times: Array, first_step: float, rtol: float, atol: float,
    out: Array,
) -> float:  # fmt: skip
    """Integrate ``dy/dt = foh_rates(t, y, params)`` from ``y0`` at 0 to ``times[-1]``.

    Writes the state at each of the increasing ``times`` into the rows of ``out`` (dense
    output between steps, the last step's state at the end) and returns the step size it
    proposes next, or :data:`TOO_SMALL_STEP` when the step size falls below ten ulps of the
    time (a non-finite state included). ``first_step <= 0`` selects the first step by
    scipy's heuristic (Hairer et al., Sec. II.4).
    """
    n = y0.size
    end = times[-1]
    K = np.empty((N_EXTENDED, n))
    y = y0.copy()
    f = foh_rates(0.0, y, params)
    h_abs = first_step if first_step > 0.0 else _initial_step(params, y, f, end, rtol, atol)
    h_abs = min(h_abs, end)
    t, j = 0.0, 0
    while t < end:
        t_old, y_old, f_old = t, y, f
        h_abs, t, y, f = _step(params, t, y, f, h_abs, end, rtol, atol, K)
        if h_abs == TOO_SMALL_STEP:
            return TOO_SMALL_STEP
        if j < times.size - 1 and times[j] <= t:
            F = _dense_coefficients(params, t_old, y_old, f_old, t - t_old, y, f, K)
            while j < times.size - 1 and times[j] <= t:
                out[j] = _dense_value(F, y_old, (times[j] - t_old) / (t - t_old))
                j += 1
    out[times.size - 1] = y
    return h_abs


@compiled
def _step(params, t, y, f, h_abs, end, rtol, atol, K):  # type: ignore[no-untyped-def]
    """One accepted step (scipy's ``RungeKutta._step_impl``): ``(next h_abs, t, y, f)``."""
    min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
    h_abs = max(h_abs, min_step)
    rejected = False
    while True:
        if not h_abs >= min_step:  # written so that a nan step ends the integration too
            return TOO_SMALL_STEP, t, y, f
        t_new = min(t + h_abs, end)
        h = t_new - t
        y_new, f_new = _rk_stages(params, t, y, f, h, K)
        scale = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
        error = _error_norm(K, h, scale)
        if error < 1.0:
            factor = MAX_FACTOR if error == 0.0 else min(MAX_FACTOR, SAFETY * error**ERROR_EXPONENT)
            if rejected:
                factor = min(1.0, factor)
            return h * factor, t_new, y_new, f_new
        # a nan error (a non-finite stage) shrinks the step like a large one, as in scipy
        shrink = SAFETY * error**ERROR_EXPONENT
        h_abs = h * (shrink if shrink > MIN_FACTOR else MIN_FACTOR)
        rejected = True


@compiled
def _rk_stages(params, t, y, f, h, K):  # type: ignore[no-untyped-def]
    """The twelve stages and the 8th-order solution (scipy's ``rk_step``)."""
    K[0] = f
    for s in range(1, N_STAGES):
        dy = np.zeros_like(y)
        for i in range(s):
            dy += A[s, i] * K[i]
        K[s] = foh_rates(t + C[s] * h, y + h * dy, params)
    increment = np.zeros_like(y)
    for i in range(N_STAGES):
        increment += B[i] * K[i]
    y_new = y + h * increment
    f_new = foh_rates(t + h, y_new, params)
    K[N_STAGES] = f_new
    return y_new, f_new


@compiled
def _error_norm(K, h, scale):  # type: ignore[no-untyped-def]
    """The 5th/3rd-order blended error estimate of DOP853 in the RMS norm of ``scale``."""
    err5 = np.zeros(scale.size)
    err3 = np.zeros(scale.size)
    for i in range(N_STAGES + 1):
        err5 += E5[i] * K[i]
        err3 += E3[i] * K[i]
    err5_2 = np.sum((err5 / scale) ** 2)
    err3_2 = np.sum((err3 / scale) ** 2)
    if err5_2 == 0.0 and err3_2 == 0.0:
        return 0.0
    return abs(h) * err5_2 / np.sqrt((err5_2 + 0.01 * err3_2) * scale.size)


@compiled
def _dense_coefficients(params, t_old, y_old, f_old, h, y, f, K):  # type: ignore[no-untyped-def]
    """The 7th-order interpolant of the last step (scipy's ``_dense_output_impl``)."""
    for s in range(N_STAGES + 1, N_EXTENDED):
        a = A_EXTRA[s - N_STAGES - 1]
        dy = np.zeros_like(y_old)
        for i in range(s):
            dy += a[i] * K[i]
        K[s] = foh_rates(t_old + C_EXTRA[s - N_STAGES - 1] * h, y_old + h * dy, params)
    F = np.empty((D.shape[0] + 3, y_old.size))
    delta = y - y_old
    F[0] = delta
    F[1] = h * f_old - delta
    F[2] = 2.0 * delta - h * (f + f_old)
    for r in range(D.shape[0]):
        row = np.zeros_like(y_old)
        for i in range(N_EXTENDED):
            row += D[r, i] * K[i]
        F[3 + r] = h * row
    return F


@compiled
def _dense_value(F, y_old, x):  # type: ignore[no-untyped-def]
    """The interpolant at the fraction ``x`` of the step (scipy's ``Dop853DenseOutput``)."""
    y = np.zeros_like(y_old)
    for i in range(F.shape[0]):
        y += F[F.shape[0] - 1 - i]
        y *= x if i % 2 == 0 else 1.0 - x
    return y + y_old


@compiled
def _initial_step(params, y0, f0, end, rtol, atol):  # type: ignore[no-untyped-def]
    """scipy's ``select_initial_step`` for a method of error-estimator order 7."""
    scale = atol + np.abs(y0) * rtol
    d0 = np.sqrt(np.mean((y0 / scale) ** 2))
    d1 = np.sqrt(np.mean((f0 / scale) ** 2))
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    h0 = min(h0, end)
    f1 = foh_rates(h0, y0 + h0 * f0, params)
    d2 = np.sqrt(np.mean(((f1 - f0) / scale) ** 2)) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / 8.0)
    return min(100.0 * h0, h1, end)


@compiled
def foh_rates(t: float, x: Array, params: Array) -> Array:
    """Eq. 4 under the FOH thrust ``u_k + t slope`` of one interval, ``params = (constants
    (15, :attr:`~scpformer.dynamics.powered_descent.RigidBodyModel.scalars`), u_k (3),
    slope (3))``."""
    return scalar_rates(params[:15], x, params[15:18] + t * params[18:21])
