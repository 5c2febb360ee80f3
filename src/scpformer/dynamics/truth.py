"""Nonlinear "truth" propagation of a chief/deputy pair under two-body + J2 gravity.

Both spacecraft are integrated together in one 12-state ODE with the Dormand-Prince 8(5,3)
scheme (``DOP853``, Hairer, Norsett & Wanner, *Solving ODEs I*, Sec. II.10). By default it
takes fixed steps (at most :data:`STEPS_PER_ORBIT` per chief orbit, each arc between impulses
split evenly) with the scheme's 7th-order dense output, and checks every step with the
embedded error estimate against the same ``rtol``/``atol`` the adaptive integrator accepts a
step with; an arc whose check fails is redone with twice the steps, and after
:data:`MAX_REFINEMENTS` the whole propagation falls back to scipy's adaptive ``solve_ivp``
(``method="adaptive"`` forces that path). A step costs the same Python overhead whatever
its size, and the fixed steps avoid ``solve_ivp``'s per-call and per-step set-up. The state is
``(r_c, v_c, r_d - r_c, v_d - v_c)`` in ECI: the chief absolute state plus the deputy's
inertial offset (Encke-style), so the tolerance acts on the relative state itself and the
relative trajectory is not limited by the round-off/truncation of the ~7000 km absolute
positions. The relative acceleration is the exact difference
``a(r_c + rho) - a(r_c)`` (no linearization).

Impulsive delta-v's are applied at given times as instantaneous velocity jumps of the
deputy, expressed in the deputy's own RTN frame at that instant.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp
from scipy.integrate._ivp import dop853_coefficients as dop853

from scpformer.dynamics.orbits import (
    J2,
    MU_EARTH,
    R_EARTH,
    OrbitalElements,
    eci_to_oe,
    eci_to_rtn,
    oe_to_eci,
    rtn_dcm,
    rtn_to_eci,
    validate_oe,
)
from scpformer.dynamics.roe import oe_to_roe

__all__ = ["METHODS", "TruthResult", "propagate_relative"]

FloatArray = NDArray[np.float64]
Rhs = Callable[[float, FloatArray], FloatArray]

METHODS = ("fixed", "adaptive")
#: Fixed steps per chief orbit (an arc between impulses takes ceil(length / step) equal
#: steps). At the default tolerances the largest DOP853 error estimate of a step is then
#: ~0.3 of what the adaptive integrator accepts (ISS-like orbit; measured 0.26).
STEPS_PER_ORBIT = 30
#: Step doublings of an arc whose error check fails before falling back to ``solve_ivp``.
MAX_REFINEMENTS = 3


def _read_only(values: ArrayLike) -> FloatArray:
    arr = np.array(values, dtype=float, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True)
class TruthResult:
    """Output of :func:`propagate_relative` at the requested output times (read-only arrays).

    The ECI states are stored; the relative RTN states, osculating elements and ROE are
    computed from them on first access (a replay check reads the RTN states only, the
    osculating-state fixed point the elements only).

    Attributes
    ----------
    t : numpy.ndarray
        Output times [s], shape ``(K,)`` (same time origin as ``t_nodes``).
    rtn : numpy.ndarray
        Deputy state relative to the chief in the chief's rotating RTN frame [m, m/s],
        shape ``(K, 6)``. At an impulse time the PRE-impulse state is reported.
    oe_chief, oe_deputy : numpy.ndarray
        Osculating classical elements ``(a, e, i, raan, argp, M)``, shape ``(K, 6)``.
    roe : numpy.ndarray
        Osculating dimensionless ROE of the deputy w.r.t. the chief, shape ``(K, 6)``.
    x_chief, x_deputy : numpy.ndarray
        ECI states ``(r, v)`` [m, m/s], shape ``(K, 6)``.
    dv_eci : numpy.ndarray
        Applied impulses expressed in ECI [m/s], shape ``(N, 3)``.
    """

    t: FloatArray
    x_chief: FloatArray
    x_deputy: FloatArray
    dv_eci: FloatArray

    def __post_init__(self) -> None:
        for name in ("t", "x_chief", "x_deputy", "dv_eci"):
            object.__setattr__(self, name, _read_only(getattr(self, name)))

    @functools.cached_property
    def rtn(self) -> FloatArray:
        c, d = self.x_chief, self.x_deputy
        return _read_only(eci_to_rtn(c[:, :3], c[:, 3:], d[:, :3], d[:, 3:]))

    @functools.cached_property
    def oe_chief(self) -> FloatArray:
        return _read_only(eci_to_oe(self.x_chief[:, :3], self.x_chief[:, 3:]))

    @functools.cached_property
    def oe_deputy(self) -> FloatArray:
        return _read_only(eci_to_oe(self.x_deputy[:, :3], self.x_deputy[:, 3:]))

    @functools.cached_property
    def roe(self) -> FloatArray:
        return _read_only(oe_to_roe(self.oe_chief, self.oe_deputy))


def _derivative_factory(j2: float) -> Callable[[list[float]], list[float]]:
    """Derivative of the 12-state ``(r_c, v_c, rho, rho_dot)`` in ECI, on lists of floats.

    Same point-mass + J2 model as :func:`~scpformer.dynamics.orbits.accel_two_body_j2`
    (checked against it in the tests), evaluated on Python floats: for one 12-state
    evaluation this is ~15x faster than numpy on a (2, 3) stack (numpy's per-call
    overhead dominates for arrays this small), and the integrator cost is all in here.
    """
    mu = MU_EARTH
    k = -1.5 * j2 * MU_EARTH * R_EARTH**2

    def acc(x: float, y: float, z: float) -> tuple[float, float, float]:
        r2 = x * x + y * y + z * z
        ir3 = 1.0 / (r2 * math.sqrt(r2))
        q = k * ir3 / r2
        c = -mu * ir3 + q * (1.0 - 5.0 * z * z / r2)
        return x * c, y * c, z * (c + 2.0 * q)

    def derivative(v: list[float]) -> list[float]:
        ax, ay, az = acc(v[0], v[1], v[2])
        bx, by, bz = acc(v[0] + v[6], v[1] + v[7], v[2] + v[8])
        return [v[3], v[4], v[5], ax, ay, az, v[9], v[10], v[11], bx - ax, by - ay, bz - az]

    return derivative


def _rhs_factory(j2: float) -> Rhs:
    """Right-hand side ``f(t, s)`` of the 12-state ODE for ``solve_ivp`` (arrays)."""
    derivative = _derivative_factory(j2)

    def rhs(_t: float, s: FloatArray) -> FloatArray:
        return np.array(derivative(s.tolist()))

    return rhs


class _StepRejectedError(Exception):
    """A fixed step failed the error check after every refinement."""


_STAGES = dop853.N_STAGES  # 12 stages of the 8th-order solution, then f(y_new) (FSAL)
_A = dop853.A  # (16, 16): rows 13-15 are the extra stages of the dense output
_B = dop853.B
# Stage s takes (1, h a_s) @ (y, K_0, .., K_{s-1}): column 0 of the augmented tableau
# multiplies the step's initial state (set to 1 after scaling by h), row 16 gives y_new.
_A_AUG = np.zeros((_A.shape[0] + 1, _A.shape[0] + 1))
_A_AUG[:-1, 1:] = _A
_A_AUG[-1, 1 : _STAGES + 1] = _B


def _error_norms(h: float, err5, err3, y, y_new, rtol: float, atol: FloatArray) -> FloatArray:
    """DOP853's scaled local error estimates of a run of steps, (S,) from (S, 12) inputs.

    The 5th- and 3rd-order embedded estimates ``err5 = E5 K``, ``err3 = E3 K`` combine as
    ``|h| e5 / sqrt((e5 + 0.01 e3) n)`` with ``e = |err / scale|^2`` on components scaled by
    ``atol + rtol max(|y|, |y_new|)`` (the estimate of Hairer's DOP853 code); a step is
    acceptable when this is at most 1, the test ``solve_ivp(method="DOP853")`` accepts a step
    with.
    """
    scale = atol + rtol * np.maximum(np.abs(y), np.abs(y_new))
    e5 = np.sum((err5 / scale) ** 2, axis=1)
    e3 = np.sum((err3 / scale) ** 2, axis=1)
    denom = np.sqrt((e5 + 0.01 * e3) * y.shape[1])
    return abs(h) * np.divide(e5, denom, out=np.zeros_like(e5), where=denom > 0.0)


def _dense_basis(theta: FloatArray) -> FloatArray:
    """Weights ``(M, 7)`` of ``F0..F6`` in DOP853's continuous extension at fractions ``theta``.

    ``y(theta) = y + theta (F0 + (1 - theta)(F1 + theta (F2 + (1 - theta)(F3 + ...))))``,
    expanded: ``theta^ceil((j+1)/2) (1 - theta)^floor((j+1)/2)`` for ``F_j``.
    """
    x = theta[:, None]
    j = np.arange(7)
    return x ** ((j + 2) // 2) * (1.0 - x) ** ((j + 1) // 2)


def _dense_coefficients(derivative, rows, Y: FloatArray, h: float, F: FloatArray) -> None:
    """``F0..F6`` of the step held in ``Y`` (see :func:`_dense_basis`), written into ``F``.

    ``Y[0]`` is the step's initial state and ``Y[1:14]`` its 12 stages and ``f(y_new)``; the
    three extra stages of the continuous extension are evaluated into ``Y[14:17]``.
    ``F0 = y_new - y = h b.K``, ``F1 = h f(y) - F0``, ``F2 = 2 F0 - h (f(y) + f(y_new))``,
    ``F3..F6 = h D.K``.
    """
    K = Y[1:]
    for s in range(_STAGES + 1, _A.shape[0]):
        Y[s + 1] = derivative(np.dot(rows[s], Y[: s + 1]).tolist())
    F[0] = np.dot(h * _B, K[:_STAGES])  # y_new - y
    F[1] = h * K[0] - F[0]
    F[2] = 2.0 * F[0] - h * (K[0] + K[_STAGES])
    F[3:] = h * np.dot(dop853.D, K)


def _fixed_arc(derivative: Callable[[list[float]], list[float]], t0: float, t1: float,
               y: FloatArray, t_eval: FloatArray, steps: int, rtol: float,
               atol: FloatArray) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    """Integrate ``[t0, t1]`` in ``steps`` equal DOP853 steps; states at ``t_eval`` and ``t1``.

    Outputs come from the 7th-order continuous extension (three extra stages in the steps
    that contain one). Raises :class:`_StepRejectedError` when a step's error estimate exceeds
    the tolerance. Row 0 of ``Y`` holds the step's initial state and row ``1 + s`` stage
    ``s``, so that every stage input is one product ``(1, h a_s) @ Y``.
    """
    h = (t1 - t0) / steps
    n_all = _A.shape[0]
    tableau = h * _A_AUG
    tableau[:, 0] = 1.0
    rows = [tableau[s, : s + 1] for s in range(n_all)]
    new_row = tableau[-1, : _STAGES + 1]
    position = (t_eval - t0) / h  # sorted; output i lies in step which[i], at its fraction
    which = np.minimum(position.astype(int), steps - 1)
    basis = _dense_basis(position - which)
    first = np.searchsorted(which, np.arange(steps + 1))  # outputs of step n: first[n:n+2]
    out = np.empty((t_eval.size, y.size))
    Y = np.empty((n_all + 1, y.size))
    F = np.empty((7, y.size))  # coefficients of the continuous extension of one step
    ys = np.empty((steps + 1, y.size))
    errs = np.empty((2, steps, y.size))
    ys[0] = Y[0] = y
    Y[1] = derivative(y.tolist())
    for n in range(steps):
        for s in range(1, _STAGES):
            Y[s + 1] = derivative(np.dot(rows[s], Y[: s + 1]).tolist())
        y_new = ys[n + 1] = np.dot(new_row, Y[: _STAGES + 1])
        Y[_STAGES + 1] = derivative(y_new.tolist())
        K = Y[1:]
        errs[0, n] = np.dot(dop853.E5, K[: _STAGES + 1])
        errs[1, n] = np.dot(dop853.E3, K[: _STAGES + 1])
        if first[n + 1] > first[n]:
            _dense_coefficients(derivative, rows, Y, h, F)
            out[first[n] : first[n + 1]] = Y[0] + np.dot(basis[first[n] : first[n + 1]], F)
        Y[0] = y_new
        Y[1] = Y[_STAGES + 1]
    norms = _error_norms(h, errs[0], errs[1], ys[:-1], ys[1:], rtol, atol)
    if not np.all(norms <= 1.0):  # also catches NaN
        raise _StepRejectedError
    return out, ys[-1].copy()


def _adaptive_arc(
    rhs: Rhs, t0: float, t1: float, y: FloatArray, t_eval: FloatArray, rtol: float, atol: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``solve_ivp`` (adaptive DOP853) over ``[t0, t1]``; states at ``t_eval`` and ``t1``."""
    sol = solve_ivp(rhs, (t0, t1), y, method="DOP853", t_eval=np.append(t_eval, t1), rtol=rtol,
                    atol=atol)  # fmt: skip
    if not sol.success:  # pragma: no cover - defensive
        raise RuntimeError(f"truth integration failed: {sol.message}")
    return sol.y[:, :-1].T, sol.y[:, -1].copy()


def _as_1d_times(x: ArrayLike, name: str) -> FloatArray:
    try:
        arr = np.atleast_1d(np.asarray(x, dtype=float))
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name}: cannot be converted to a float array ({exc})") from exc
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array of times, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or inf")
    return arr


def _propagate_arcs(
    y: FloatArray,
    t_nodes: FloatArray,
    dv: FloatArray,
    t_out: FloatArray,
    arc: Callable[[float, float, FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
) -> tuple[FloatArray, FloatArray]:
    """States at ``t_out`` (pre-impulse at a node) and the impulses in ECI, arc by arc.

    Integration arcs break only at nodes with a non-zero impulse; ``arc(t0, t1, y0, t_eval)``
    integrates one of them and returns the states at ``t_eval`` (inside ``[t0, t1)``) and
    at ``t1``.
    """
    order = np.argsort(t_out, kind="stable")
    y_out = np.empty((t_out.size, 12))
    dv_eci = np.zeros((t_nodes.size, 3))
    t_end = max(t_nodes[-1], t_out.max())
    kicks = np.flatnonzero(np.any(dv != 0.0, axis=1)).tolist()
    starts = [(t_nodes[0], None)] + [(t_nodes[k], k) for k in kicks]
    if len(starts) > 1 and starts[1][0] == starts[0][0]:
        starts = starts[1:]  # impulse at the initial node
    ts = t_out[order]
    j = 0  # index into sorted outputs
    for s_idx, (t0, k) in enumerate(starts):
        t1 = starts[s_idx + 1][0] if s_idx + 1 < len(starts) else t_end
        while j < ts.size and ts[j] == t0:  # pre-impulse outputs at the node
            y_out[order[j]] = y
            j += 1
        if k is not None:
            C = rtn_dcm(y[0:3] + y[6:9], y[3:6] + y[9:12])
            dv_eci[k] = C.T @ dv[k]
            y = y.copy()
            y[9:12] += dv_eci[k]
        if t1 <= t0:
            continue
        jj = int(np.searchsorted(ts, t1, side="left"))
        y_out[order[j:jj]], y = arc(t0, t1, y, ts[j:jj])
        j = jj
    y_out[order[j:]] = y  # outputs at t_end (after the last node, or at the last node)
    return y_out, dv_eci


def propagate_relative(
    oe_chief0: ArrayLike | OrbitalElements,
    rtn0: ArrayLike,
    t_nodes: ArrayLike,
    dv_rtn: ArrayLike | None = None,
    t_out: ArrayLike | None = None,
    *,
    j2: bool | float = True,
    rtol: float = 1e-10,
    atol_pos: float = 1e-7,
    atol_vel: float = 1e-10,
    method: str = "fixed",
) -> TruthResult:
    """Propagate chief and deputy under two-body + J2 with impulses; return relative states.

    Parameters
    ----------
    oe_chief0
        Chief OSCULATING classical elements at ``t_nodes[0]``, shape ``(6,)``.
    rtn0
        Deputy relative RTN state at ``t_nodes[0]`` [m, m/s], shape ``(6,)``, in the
        convention of :func:`scpformer.dynamics.orbits.eci_to_rtn`.
    t_nodes
        Strictly increasing node times [s], shape ``(N,)``; the initial state holds at
        ``t_nodes[0]`` and impulse ``k`` is applied at ``t_nodes[k]``.
    dv_rtn
        Impulses [m/s], shape ``(N, 3)``, each expressed in the deputy's RTN frame at the
        instant it is applied. ``None`` means no impulses (free drift).
    t_out
        Output times [s], shape ``(K,)``, each ``>= t_nodes[0]`` (may extend past the last
        node). Defaults to ``t_nodes``. At an impulse time the pre-impulse state is
        returned, matching ``x(t_{i+1}) = Phi (x(t_i) + B u(t_i))``.
    j2
        ``True`` for two-body + J2 (``J2`` of :mod:`orbits`), ``False`` for two-body only,
        or a float value of the J2 coefficient.
    rtol, atol_pos, atol_vel
        DOP853 tolerances; the absolute ones apply to position [m] and velocity [m/s]
        components. Every fixed step meets them (see the module docstring).
    method
        ``"fixed"`` (checked fixed steps, falling back to adaptive) or ``"adaptive"``
        (scipy's ``solve_ivp``, the reference).

    Returns
    -------
    TruthResult
        Relative RTN states, osculating elements and ROE at ``t_out``.

    Raises
    ------
    ValueError
        On non-physical elements, wrong shapes, NaN/inf, non-increasing ``t_nodes`` or an
        output time before ``t_nodes[0]``.
    """
    oe_c = validate_oe(oe_chief0, "oe_chief0")
    if oe_c.shape != (6,):
        raise ValueError(f"oe_chief0: expected shape (6,), got {oe_c.shape}")
    rtn0 = np.asarray(rtn0, dtype=float)
    if rtn0.shape != (6,):
        raise ValueError(f"rtn0: expected shape (6,), got {rtn0.shape}")
    if not np.all(np.isfinite(rtn0)):
        raise ValueError("rtn0: contains NaN or inf")
    t_nodes = _as_1d_times(t_nodes, "t_nodes")
    if t_nodes.size == 0:
        raise ValueError("t_nodes: must contain at least one time")
    if np.any(np.diff(t_nodes) <= 0.0):
        raise ValueError("t_nodes: must be strictly increasing")
    if dv_rtn is None:
        dv = np.zeros((t_nodes.size, 3))
    else:
        dv = np.asarray(dv_rtn, dtype=float)
        if dv.shape != (t_nodes.size, 3):
            raise ValueError(f"dv_rtn: expected shape ({t_nodes.size}, 3), got {dv.shape}")
        if not np.all(np.isfinite(dv)):
            raise ValueError("dv_rtn: contains NaN or inf")
    t_out = t_nodes.copy() if t_out is None else _as_1d_times(t_out, "t_out")
    if t_out.size == 0:
        raise ValueError("t_out: must contain at least one time")
    if np.any(t_out < t_nodes[0]):
        raise ValueError("t_out: output times must be >= t_nodes[0]")
    j2_val = (J2 if j2 else 0.0) if isinstance(j2, bool) else float(j2)
    if method not in METHODS:
        raise ValueError(f"method: must be one of {METHODS}, got {method!r}")

    r_c, v_c = oe_to_eci(oe_c)
    r_d, v_d = rtn_to_eci(r_c, v_c, rtn0)
    y = np.concatenate([r_c, v_c, r_d - r_c, v_d - v_c])
    derivative = _derivative_factory(j2_val)
    rhs = _rhs_factory(j2_val)
    atol = np.array([atol_pos] * 3 + [atol_vel] * 3 + [atol_pos] * 3 + [atol_vel] * 3)

    def adaptive(t0: float, t1: float, y0: FloatArray, t_eval: FloatArray):
        return _adaptive_arc(rhs, t0, t1, y0, t_eval, rtol, atol)

    step = 2.0 * math.pi * math.sqrt(oe_c[0] ** 3 / MU_EARTH) / STEPS_PER_ORBIT

    def fixed(t0: float, t1: float, y0: FloatArray, t_eval: FloatArray):
        steps = max(1, math.ceil((t1 - t0) / step - 1e-9))
        for refinement in range(MAX_REFINEMENTS + 1):
            try:
                return _fixed_arc(derivative, t0, t1, y0, t_eval, steps << refinement, rtol, atol)
            except _StepRejectedError:
                continue
        raise _StepRejectedError

    if method == "fixed":
        try:
            y_out, dv_eci = _propagate_arcs(y, t_nodes, dv, t_out, fixed)
        except _StepRejectedError:
            y_out, dv_eci = _propagate_arcs(y, t_nodes, dv, t_out, adaptive)
    else:
        y_out, dv_eci = _propagate_arcs(y, t_nodes, dv, t_out, adaptive)

    x_c = y_out[:, 0:6]
    return TruthResult(t=t_out, x_chief=x_c, x_deputy=x_c + y_out[:, 6:12], dv_eci=dv_eci)
