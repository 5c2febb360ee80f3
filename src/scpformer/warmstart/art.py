"""ART warm starts: Algorithms 1-2 of the ART paper, the post hoc check of the robust paper.

Generation (ART paper, Sec. 3, Algorithms 1 and 2; robust paper, Sec. 3, "Inference"). With
the sequence model's inference interface (``start``, ``predict_action``, ``predict_state``,
see ``ART_CONTRACT.md``), every instance of a batch starts from its initial state ``x(t_1)``,
the desired reward-to-go ``R(t_1)`` and constraint-to-go ``C(t_1)``; at each step ``k``:

1. the model predicts ``u_k`` from the tokens ``R(t_k), C(t_k), x_k`` (one call);
2. ``R(t_{k+1}) = R(t_k) - (-|u_k|_2)`` and ``C(t_{k+1}) = C(t_k) - C_k`` (Eqs. 4-5), with
   ``C_k`` the instantaneous constraint violation of the family (ART Eq. 21: keep-out zone;
   robust Eq. 7: passive safety with the chance margin) at ``(x_k, u_k)``;
3. the next state is the family's dynamics at ``(x_k, u_k)`` (Algorithm 2, dynamics in the
   loop: ``Phi_k (x_k + B_k u_k)`` with the rendezvous' exact STM and control input matrix;
   the robust family's plan dynamics, by default the nonlinear mean-element flow its SCvx*
   plans obey) or the model's prediction at the ``u_k`` token (Algorithm 1, transformer
   only).

Signs follow the dataset (:func:`scpformer.problems.rendezvous.constraints.reward_to_go`):
``R(t_k) = -sum_{j >= k} |dv_j|_2 <= 0``, so the update adds ``|u_k|`` and the default
``R(t_1) = -J_CVX`` (the cost of the convex warm start: Problem 2 for the rendezvous, the
TPBVP for the robust family) is negative; ``C(t_1) = 0`` by default (both papers).

States are fed in the model's frame (``rtn``: ``Psi_k x_k``, ART Eq. 9; ``roe``: ``x_k``) and
the returned guess is always in the solvers' scaled mean ROE. Algorithm 1 outputs N states
``x_0 .. x_{N-1}``; the final node ``x_N`` (outside the model's N-step context) is propagated
from ``x_{N-1}`` through the family's dynamics (step 3) in both modes.

Post hoc acceptance check (robust paper, Eq. 8 and Sec. 5): with the realized
``R_ART = -sum |u|`` and ``C_ART`` (the generated trajectory's constraint-to-go at ``t_1``),
``E_R = (R_ART - R_des) / R_des`` and ``E_C = C_ART - C_des``; the guess is accepted when
``-1.5 <= 100 E_R <= 3.5`` and ``0 <= E_C <= 2``, otherwise the convex warm start is used.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from scpformer.scp.solution import Trajectory
from scpformer.scp.warmstart import WarmStart, WarmStartRecord, WarmStartResult, trajectory_cost
from scpformer.validation import shown
from scpformer.warmstart.families import ART_FRAMES, Batch, art_family

ArtMode = Literal["dynamics", "transformer"]
ART_MODES = ("dynamics", "transformer")  # Algorithm 2, Algorithm 1


# ======================================================================================
# post hoc acceptance check (robust paper, Eq. 8)
# ======================================================================================
@dataclass(frozen=True)
class Acceptance:
    """Outcome of the post hoc check: the errors of Eq. 8 and the decision."""

    accepted: bool
    E_R: float  # (R_ART - R_des) / R_des [-]
    E_C: float  # C_ART - C_des [-]
    reason: str


@dataclass(frozen=True, kw_only=True)
class AcceptanceCheck:
    """Acceptance region of the post hoc check (robust paper, Sec. 5, "Post hoc ...")."""

    e_r_percent: tuple[float, float] = (-1.5, 3.5)  # bounds on 100 E_R [%]
    e_c: tuple[float, float] = (0.0, 2.0)  # bounds on E_C [-]

    def __post_init__(self) -> None:
        for name in ("e_r_percent", "e_c"):
            bounds = tuple(float(v) for v in getattr(self, name))
            if len(bounds) != 2 or not all(map(math.isfinite, bounds)) or bounds[0] > bounds[1]:
                raise ValueError(f"{name} must be finite (low, high) with low <= high, got "
                                 f"{shown(getattr(self, name))}")  # fmt: skip
            object.__setattr__(self, name, bounds)

    def evaluate(
        self, *, rtg_desired: float, ctg_desired: float, rtg_realized: float, ctg_realized: float
    ) -> Acceptance:
        """Eq. 8: ``E_R = (R_ART - R_des) / R_des``, ``E_C = C_ART - C_des``, and the decision.

        ``rtg_*`` are reward-to-go values at ``t_1`` (negative costs, the dataset's sign).
        """
        E_C = float(ctg_realized - ctg_desired)
        if rtg_desired == 0.0:
            percent = 0.0 if rtg_realized == 0.0 else math.inf
        else:  # 100 E_R, multiplied first so that decimal bounds hold exactly
            percent = float(100.0 * (rtg_realized - rtg_desired) / rtg_desired)
        (r_lo, r_hi), (c_lo, c_hi) = self.e_r_percent, self.e_c
        ok_r, ok_c = r_lo <= percent <= r_hi, c_lo <= E_C <= c_hi
        E_R = percent / 100.0
        text = f"100 E_R = {percent:.3g} in [{r_lo:g}, {r_hi:g}]"
        text_c = f"E_C = {E_C:g} in [{c_lo:g}, {c_hi:g}]"
        reason = "; ".join([
            text if ok_r else text.replace(" in ", " not in "),
            text_c if ok_c else text_c.replace(" in ", " not in "),
        ])  # fmt: skip
        return Acceptance(ok_r and ok_c, E_R, E_C, reason)


def preferred_guess(
    check: AcceptanceCheck,
    *,
    rtg_desired: float,
    ctg_desired: float,
    candidates: dict[str, tuple[float, float]],
) -> tuple[str, dict[str, Acceptance]]:
    """The guess the post hoc check prefers among ``candidates``, and each one's decision.

    ``candidates`` maps a name to the guess's cost ``sum |u|`` [m/s] and constraint-to-go
    ``C(t_1)``; each is put through Eq. 8 against the desired ``R`` and ``C``
    (:meth:`AcceptanceCheck.evaluate`). Preferred: an accepted guess first, then the fewer
    violations left (smaller ``E_C``), then the cost nearer the desired one (smaller
    ``|E_R|``); a tie keeps the order of ``candidates``.
    """
    if not candidates:
        raise ValueError("candidates must name at least one guess")
    decisions = {
        name: check.evaluate(
            rtg_desired=rtg_desired, ctg_desired=ctg_desired, rtg_realized=-cost, ctg_realized=ctg
        )
        for name, (cost, ctg) in candidates.items()
    }
    order = list(candidates)
    best = min(order, key=lambda name: (not decisions[name].accepted, decisions[name].E_C,
                                        abs(decisions[name].E_R), order.index(name)))  # fmt: skip
    return best, decisions


# ======================================================================================
# generation: Algorithms 1 and 2, batched
# ======================================================================================
@dataclass(frozen=True)
class ArtRollout:
    """B generated trajectories and the conditioning fed to the model."""

    x: np.ndarray  # (B, N+1, 6) scaled mean ROE [m] (the guess's states)
    u: np.ndarray  # (B, N, 3) impulses in RTN [m/s]
    states: np.ndarray  # (B, N, 6) states fed to the model, in its frame
    rtg: np.ndarray  # (B, N) R(t_k) fed at step k [m/s]
    ctg: np.ndarray  # (B, N) C(t_k) fed at step k
    violations: np.ndarray  # (B, N) instantaneous violations C_k (ints)
    time_s: float  # wall time of the whole batch [s]


@dataclass(frozen=True)
class ArtPrefix:
    """The known steps ``0 .. k-1`` of B histories, as :func:`generate` feeds them first.

    Physical units, states in the model's frame (``rtn``: ``Psi_j x_j``; ``roe``: ``x_j``):
    ``states`` (B, k, 6), ``actions`` (B, k, 3) [m/s], ``rtg`` (B, k) ``R(t_j)`` [m/s] and
    ``ctg`` (B, k) ``C(t_j)``. :func:`flown_prefix` builds it from a flown trajectory.
    """

    states: np.ndarray
    actions: np.ndarray
    rtg: np.ndarray
    ctg: np.ndarray

    def __post_init__(self) -> None:
        for name in ("states", "actions", "rtg", "ctg"):
            value = np.asarray(getattr(self, name), dtype=float)
            if not np.all(np.isfinite(value)):
                raise ValueError(f"prefix {name} must be finite")
            object.__setattr__(self, name, value)
        if self.states.ndim != 3 or self.states.shape[2] != 6:
            raise ValueError(f"prefix states must be (B, k, 6), got {self.states.shape}")
        b, k = self.states.shape[:2]
        for name, shape in (("actions", (b, k, 3)), ("rtg", (b, k)), ("ctg", (b, k))):
            if getattr(self, name).shape != shape:
                got = getattr(self, name).shape
                raise ValueError(f"prefix {name} must be {shape} to match states (B, k, 6) = "
                                 f"{self.states.shape}, got {got}")  # fmt: skip

    @property
    def k(self) -> int:
        """Number of known steps."""
        return int(self.states.shape[1])

    def check(self, size: int) -> int:
        """``k``, after checking that the prefix holds ``size`` histories."""
        if self.states.shape[0] != size:
            raise ValueError(f"the prefix holds {self.states.shape[0]} histories, the batch {size}")
        return self.k


def flown_prefix(
    history: Batch,
    family: Any,
    x: np.ndarray,
    u: np.ndarray,
    *,
    frame: str,
    rtg_k: np.ndarray,
    ctg_k: np.ndarray,
) -> ArtPrefix:
    """The ART context of a re-plan at node ``k``: the flown steps ``0 .. k-1`` as tokens.

    Parameters
    ----------
    history
        The whole problems (N impulses from ``t_0``) the histories were flown on (the family
        adapter's batch): ``Psi_j`` maps node ``j``'s state to the model's frame, as the
        training data do (``p_rtn = Psi(t_j) x_j``,
        :func:`scpformer.data.rendezvous_family.sequence_fields`), and the family's ``C_j``
        is evaluated at node ``j`` of that problem.
    family
        The family adapter (``violations``).
    x, u
        (B, k, 6) scaled mean ROE [m] of nodes ``0 .. k-1`` and (B, k, 3) impulses applied
        there [m/s], ``0 <= k < N``.
    frame
        The model's state frame, ``rtn`` or ``roe``.
    rtg_k, ctg_k
        (B,) ``R(t_k)`` and ``C(t_k)`` conditioned at node ``k``.

    The reward and constraint tokens of the prefix follow from those at ``k`` by Eqs. 4-5
    run backwards, as the dataset defines them along a trajectory (its own cost- and
    constraint-to-go, :func:`~scpformer.problems.rendezvous.constraints.reward_to_go`):
    ``R(t_j) = R(t_k) - sum_{j <= i < k} |u_i|`` and ``C(t_j) = C(t_k) + sum_{j <= i < k}
    C_i``.
    """
    _check_choice("frame", frame, ART_FRAMES)
    x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
    size, n = history.x0.shape[0], history.n_steps
    if x.ndim != 3 or x.shape[0] != size or x.shape[2] != 6:
        raise ValueError(f"x must be ({size}, k, 6) (the history's {size} problems), got {x.shape}")
    k = x.shape[1]
    if not 0 <= k < n:
        raise ValueError(f"a prefix of k = {k} nodes must have 0 <= k < N = {n} (the history's N)")
    if u.shape != (size, k, 3):
        raise ValueError(f"u must be ({size}, {k}, 3) to match x {x.shape}, got {u.shape}")
    rtg_k, ctg_k = np.asarray(rtg_k, dtype=float), np.asarray(ctg_k, dtype=float)
    for name, value in (("rtg_k", rtg_k), ("ctg_k", ctg_k)):
        if value.shape != (size,):
            raise ValueError(f"{name} must have shape ({size},), got {value.shape}")
    states = np.empty_like(x)
    violations = np.zeros((size, k))
    for j in range(k):
        states[:, j] = history.to_frame(j, x[:, j], frame)
        violations[:, j] = family.violations(history, j, x[:, j], u[:, j])
    spent = np.cumsum(np.linalg.norm(u, axis=2)[:, ::-1], axis=1)[:, ::-1]  # sum_{i >= j}
    flagged = np.cumsum(violations[:, ::-1], axis=1)[:, ::-1]
    return ArtPrefix(states, u, rtg_k[:, None] - spent, ctg_k[:, None] + flagged)


def _feed_prefix(
    model: Any, cache: Any, prefix: ArtPrefix, normalization: Any, tensor: Any
) -> None:
    """Feed ``prefix`` into a fresh cache: one pass with ``model.feed_prefix`` (optional in
    the inference interface), else step by step with teacher forcing."""
    tokens = (
        tensor(normalization.encode("rtg", prefix.rtg[..., None])),  # (B, k, 1)
        tensor(normalization.encode("ctg", prefix.ctg[..., None])),
        tensor(normalization.encode("state", prefix.states)),  # rows 0 .. k-1
        tensor(normalization.encode("action", prefix.actions)),
    )
    feed = getattr(model, "feed_prefix", None)
    if callable(feed):
        feed(cache, *tokens)
        return
    feed_action = getattr(model, "feed_action", None) or model.predict_state
    for j in range(prefix.k):
        model.predict_action(cache, *(t[:, j] for t in tokens[:3]))
        feed_action(cache, tokens[3][:, j])


def _check_choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    if value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")
    return str(value)


def _device(model: Any) -> Any:
    parameters = getattr(model, "parameters", None)
    if callable(parameters):
        for p in parameters():
            return p.device
    return "cpu"


def _check_context(model: Any, n_steps: int) -> None:
    context = getattr(getattr(model, "config", None), "context", None)
    if context is not None and context < n_steps:
        raise ValueError(
            f"the model's context ({context} steps) is shorter than the horizon (N = {n_steps})"
        )


def generate(
    model: Any,
    normalization: Any,
    batch: Batch,
    family: Any,
    *,
    frame: str,
    art_mode: str,
    rtg0: np.ndarray,
    ctg0: np.ndarray,
    prefix: ArtPrefix | None = None,
) -> ArtRollout:
    """Algorithm 2 (``art_mode="dynamics"``) or 1 (``"transformer"``) for a whole batch.

    Parameters
    ----------
    model
        A sequence model with the inference interface of ``ART_CONTRACT.md``.
    normalization
        The model's normalization (``encode`` / ``decode`` per key and time step).
    batch, family
        Stacked instances (:meth:`~scpformer.warmstart.families.RendezvousArtFamily.batch`)
        and their family adapter (dynamics, violations, target token).
    frame
        State frame of the model, ``rtn`` or ``roe``.
    art_mode
        ``dynamics`` (Algorithm 2) or ``transformer`` (Algorithm 1).
    rtg0, ctg0
        ``R(t_1)`` (<= 0, [m/s]) and ``C(t_1)`` of each instance, (B,); with a ``prefix`` of
        ``k`` steps, ``R(t_k)`` and ``C(t_k)`` at the first generated step.
    prefix
        The known steps ``0 .. k-1`` of a history (:class:`ArtPrefix`, e.g. the flown part of
        a closed-loop rendezvous, :func:`flown_prefix`): fed first, in one pass, and the
        generation continues from time step ``k`` with ``batch`` holding the remaining
        ``N - k`` steps (its ``x0`` the state at node ``k``). The tokens of step ``j`` use
        time step ``k + j`` (the time-step embedding and the normalization's row), so the
        model sees the true time steps. ``None`` (or ``k = 0``) is the generation from time
        step 0.
    """
    import torch

    start = time.perf_counter()
    n, size = batch.n_steps, batch.x0.shape[0]
    _check_choice("frame", frame, ART_FRAMES)
    _check_choice("art_mode", art_mode, ART_MODES)
    for name, value in (("rtg0", rtg0), ("ctg0", ctg0)):
        if np.shape(value) != (size,) or not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite with shape ({size},), got {np.shape(value)}")
    k0 = 0 if prefix is None else prefix.check(size)
    _check_context(model, k0 + n)
    device = _device(model)

    def tensor(value: np.ndarray) -> Any:
        return torch.as_tensor(np.asarray(value, dtype=np.float64), dtype=torch.float32,
                               device=device)  # fmt: skip

    def numpy(value: Any) -> np.ndarray:
        if isinstance(value, torch.Tensor):
            value = value.detach().to("cpu", torch.float64).numpy()
        return np.asarray(value, dtype=np.float64)

    target = None
    if family.has_target and getattr(getattr(model, "config", None), "target_dim", 6):
        target = tensor(normalization.encode("target", batch.to_frame(n, batch.x_target, frame)))
    x = np.empty((size, n + 1, 6))
    u = np.empty((size, n, 3))
    states = np.empty((size, n, 6))
    rtg, ctg = np.empty((size, n)), np.empty((size, n))
    violations = np.zeros((size, n), dtype=int)
    x[:, 0] = batch.x0
    states[:, 0] = batch.to_frame(0, batch.x0, frame)
    R, C = np.asarray(rtg0, dtype=float).copy(), np.asarray(ctg0, dtype=float).copy()
    # Algorithm 2 reads no x_hat: with feed_action (optional in the contract) the u_k token
    # goes through with step k+1's tokens, one pass through the model per step instead of two.
    feed_action = getattr(model, "feed_action", None) or model.predict_state
    with torch.no_grad():
        cache = model.start(size, target)
        if k0:
            _feed_prefix(model, cache, prefix, normalization, tensor)
        for k in range(n):
            rtg[:, k], ctg[:, k] = R, C
            u_norm = model.predict_action(
                cache,
                tensor(normalization.encode("rtg", R[:, None], step=k0 + k)),
                tensor(normalization.encode("ctg", C[:, None], step=k0 + k)),
                tensor(normalization.encode("state", states[:, k], step=k0 + k)),
            )  # (B, 3)
            u[:, k] = normalization.decode("action", numpy(u_norm), step=k0 + k)
            violations[:, k], x_next = family.transition(batch, k, x[:, k], u[:, k])
            R = R + np.linalg.norm(u[:, k], axis=1)  # R(t_{k+1}) = R(t_k) - (-|u_k|)
            C = C - violations[:, k]
            if k == n - 1:
                x[:, n] = x_next
                break
            if art_mode == "transformer":
                predicted = model.predict_state(cache, u_norm)  # feeds the u_k token
                states[:, k + 1] = normalization.decode("state", numpy(predicted), step=k0 + k + 1)
                x[:, k + 1] = batch.from_frame(k + 1, states[:, k + 1], frame)
            else:
                feed_action(cache, u_norm)
                x[:, k + 1] = x_next
                states[:, k + 1] = batch.to_frame(k + 1, x_next, frame)
    return ArtRollout(x, u, states, rtg, ctg, violations, time.perf_counter() - start)


# ======================================================================================
# the provider
# ======================================================================================
@dataclass(frozen=True)
class FlownHistory:
    """What a closed-loop run flew before node ``k``: the ART context of a re-plan there.

    ``instance`` is the whole problem the run flies (N impulses from ``t_0``); ``x`` (k, 6)
    the scaled mean ROE [m] of nodes ``0 .. k-1`` as the guidance knows them and ``u`` (k, 3)
    the impulses applied there [m/s]. The re-plan's remaining problem holds the other
    ``N - k`` impulses, from node ``k`` (its initial state: the estimate at ``t_k``).
    """

    instance: Any
    x: np.ndarray
    u: np.ndarray

    def __post_init__(self) -> None:
        x, u = np.asarray(self.x, dtype=float), np.asarray(self.u, dtype=float)
        n = int(self.instance.scenario.n_nodes)
        if x.ndim != 2 or x.shape[1] != 6:
            raise ValueError(f"history x must be (k, 6), got {x.shape}")
        if not 0 <= x.shape[0] < n:
            raise ValueError(f"history of k = {x.shape[0]} flown nodes: must be 0 <= k < N = {n}")
        if u.shape != (x.shape[0], 3):
            raise ValueError(f"history u must be ({x.shape[0]}, 3) to match x {x.shape}, "
                             f"got {u.shape}")  # fmt: skip
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(u))):
            raise ValueError("history x and u must be finite")
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "u", u)

    @property
    def k(self) -> int:
        """The node of the re-plan: number of flown nodes."""
        return int(self.x.shape[0])


class ArtWarmStart:
    """ART as a warm start provider (Algorithm 2 by default), with the post hoc check.

    Parameters
    ----------
    model
        Sequence model with ``start`` / ``predict_action`` / ``predict_state``.
    normalization
        Its :class:`~scpformer.models.normalization.ArtNormalization` (or anything with the
        same ``encode`` / ``decode``).
    frame
        State frame the model was trained in: ``rtn`` or ``roe``.
    family
        ``rendezvous`` or ``robust-rendezvous``.
    art_mode
        ``dynamics`` (Algorithm 2) or ``transformer`` (Algorithm 1).
    rtg
        ``R(t_1)`` [m/s], <= 0 (the dataset's sign); default ``-J_CVX`` per instance.
    ctg
        ``C(t_1)`` >= 0; default 0.
    acceptance
        The post hoc check (robust paper Eq. 8) or None to accept every guess; ``"family"``
        applies :class:`AcceptanceCheck` to the robust family and none to the rendezvous
        family (the ART paper always warm-starts with ART).
    mode
        Robust family: passive safety ``chance`` or ``deterministic`` (the Eq. 7 budget).
    config
        Solver configuration of the convex warm start (``J_CVX`` and the fallback); for the
        robust family its ``dynamics`` is also the model of the rollout and of ``C(t_1)``.
    fallback
        Warm start used when the check rejects ART's guess; default the family's convex one.
    """

    def __init__(
        self,
        model: Any,
        normalization: Any,
        *,
        frame: str = "rtn",
        family: str = "rendezvous",
        art_mode: ArtMode = "dynamics",
        rtg: float | None = None,
        ctg: float = 0.0,
        acceptance: AcceptanceCheck | Literal["family"] | None = "family",
        mode: str = "chance",
        config: Any = None,
        fallback: WarmStart | None = None,
    ) -> None:
        self.model, self.normalization = model, normalization
        self.frame = _check_choice("frame", frame, ART_FRAMES)
        self.art_mode = _check_choice("art_mode", art_mode, ART_MODES)
        self.adapter = art_family(family, mode, getattr(config, "dynamics", "nonlinear"))
        self.family, self.mode = family, mode
        if rtg is not None and not (math.isfinite(rtg) and rtg <= 0.0):
            raise ValueError(
                f"rtg must be a finite R(t_1) <= 0 (R = -sum |dv|, the dataset's sign), got {rtg}"
            )
        if not (math.isfinite(ctg) and ctg >= 0.0):
            raise ValueError(f"ctg must be a finite C(t_1) >= 0, got {ctg}")
        self.rtg, self.ctg = rtg, float(ctg)
        if acceptance == "family":
            acceptance = AcceptanceCheck() if family == "robust-rendezvous" else None
        if acceptance is not None and not isinstance(acceptance, AcceptanceCheck):
            raise ValueError(f"acceptance must be an AcceptanceCheck or None, got {acceptance!r}")
        self.acceptance = acceptance
        self.fallback = fallback if fallback is not None else self.adapter.fallback(config)
        for name in ("encode", "decode"):
            if not callable(getattr(normalization, name, None)):
                raise ValueError(f"normalization must have an {name}(key, value, step) method")
        for name in ("start", "predict_action", "predict_state"):
            if not callable(getattr(model, name, None)):
                raise ValueError(f"model must have the inference method {name}()")

    @classmethod
    def from_checkpoint(
        cls,
        path: str | Path | Any,
        *,
        family: str | None = None,
        frame: str | None = None,
        device: str = "cpu",
        **kwargs: Any,
    ) -> ArtWarmStart:
        """Wrap the model of ``RUN/checkpoint.pt``, the file, or a loaded ``Checkpoint``.

        A path goes through :func:`scpformer.models.checkpoint.load_checkpoint`, which checks
        ``family`` / ``frame`` when given; a loaded checkpoint is checked here. The other
        keyword arguments are those of the constructor.
        """
        ckpt = path
        if isinstance(path, str | Path):
            from scpformer.models.checkpoint import load_checkpoint

            ckpt = load_checkpoint(path, family=family, frame=frame, device=device)
        for name, wanted in (("family", family), ("frame", frame)):
            if wanted is not None and getattr(ckpt, name) != wanted:
                raise ValueError(f"{path}: a {getattr(ckpt, name)} checkpoint, not {wanted}")
        if getattr(ckpt, "normalization", None) is None:
            raise ValueError(f"{path}: the checkpoint holds no ART normalization")
        return cls(ckpt.model, ckpt.normalization, frame=ckpt.frame, family=ckpt.family,
                   **kwargs)  # fmt: skip

    # -- the WarmStart interface ----------------------------------------------------------
    def guess(self, instance: Any, history: FlownHistory | None = None) -> WarmStartResult:
        """ART's guess for one instance (see :meth:`guess_batch`)."""
        return self.guess_batch([instance], None if history is None else [history])[0]

    def guess_batch(
        self, instances: Sequence[Any], histories: Sequence[FlownHistory] | None = None
    ) -> list[WarmStartResult]:
        """ART's guesses for many instances, generated as batches through the model.

        Each result's record gives ``source="art"``, the total time (convex warm start, when
        solved, plus this instance's share of the batched generation), the cost and
        ``C(t_1)`` of the returned guess, the acceptance decision and, when rejected, the
        fallback. ``details`` holds ``R(t_1)``, ``C(t_1)``, ``E_R``, ``E_C``, ART's own cost
        and constraint-to-go and ``k``, the time step the generation started from.

        Mid-horizon (closed loop, Celestini et al., RA-L 2024): with ``histories``, instance
        ``i`` is the remaining problem of a run at node ``k = histories[i].k`` (``N - k``
        impulses from the current estimate) and ``histories[i]`` what was flown before. The
        model's context is the flown prefix (:func:`flown_prefix`: the states of nodes
        ``0 .. k-1`` in the model's frame, the applied impulses, the reward and constraint
        tokens recomputed along them) and Algorithm 1 or 2 continues from time step ``k``
        with the estimate as the state token, the time-step embedding and the normalization
        at their true time steps. The reward-to-go at node ``k`` is the ART paper's
        conditioning (Sec. 3, Algorithm 2: ``R(t_1) = -J_CVX``) applied to the problem posed
        at ``t_k``: ``R(t_k) = -J_CVX(t_k)``, the cost of the convex Problem 2 of the
        remaining problem (the cold start of the re-plan, solved here), and ``C(t_k) = 0``
        (or the constructor's ``rtg`` / ``ctg``). Not the initial ``R(t_1)`` minus the cost
        already spent: navigation, execution and process errors change what the remaining
        transfer costs, and the convex problem from the estimate measures it. The prefix's
        tokens follow by Eqs. 4-5 (``R(t_j) = R(t_k) - sum_{j <= i < k} |u_i|``), the
        dataset's cost-to-go of the flown prefix continued by the remaining plan. Instances
        with equal ``k`` are generated as one batch.
        """
        if not instances:
            return []
        if histories is not None:
            if len(histories) != len(instances):
                raise ValueError(f"{len(histories)} histories for {len(instances)} instances")
            for instance, history in zip(instances, histories, strict=True):
                if not isinstance(history, FlownHistory):
                    raise ValueError(f"histories must be FlownHistory, got "
                                     f"{type(history).__name__}")  # fmt: skip
                n_full, n_rem = history.instance.scenario.n_nodes, instance.scenario.n_nodes
                if n_rem + history.k != n_full:
                    raise ValueError(
                        f"a remaining problem of {n_rem} impulses after k = {history.k} flown "
                        f"nodes: the history's N = {n_full} needs N - k = {n_full - history.k}"
                    )
        ks = np.zeros(len(instances), dtype=int) if histories is None else np.array(
            [h.k for h in histories])  # fmt: skip
        batches = {k: self.adapter.batch([instances[i] for i in np.flatnonzero(ks == k)])
                   for k in np.unique(ks)}  # one N per k; checks the instances first  # fmt: skip
        convex: list[WarmStartResult | None] = [None] * len(instances)
        if self.rtg is None:
            convex = [self.fallback.guess(instance) for instance in instances]
        rtg0 = np.array([self.rtg if c is None else -c.record.cost for c in convex], dtype=float)
        ok = np.flatnonzero(np.isfinite(rtg0))
        results: list[WarmStartResult | None] = [None] * len(instances)
        for i in np.flatnonzero(~np.isfinite(rtg0)):
            results[i] = self._without_rtg(convex[i])
        for k in np.unique(ks[ok]):
            group = ok[ks[ok] == k]
            start = time.perf_counter()
            sub = batches[k] if group.size == (ks == k).sum() else self.adapter.batch(
                [instances[i] for i in group])  # fmt: skip
            prefix = None
            if histories is not None:
                flown = [histories[i] for i in group]
                prefix = flown_prefix(
                    self.adapter.batch([h.instance for h in flown]), self.adapter,
                    np.stack([h.x for h in flown]), np.stack([h.u for h in flown]),
                    frame=self.frame, rtg_k=rtg0[group], ctg_k=np.full(group.size, self.ctg),
                )  # fmt: skip
            rollout = generate(self.model, self.normalization, sub, self.adapter,
                               frame=self.frame, art_mode=self.art_mode, rtg0=rtg0[group],
                               ctg0=np.full(group.size, self.ctg), prefix=prefix)  # fmt: skip
            share = (time.perf_counter() - start) / group.size
            for j, i in enumerate(group):
                results[i] = self._decide(instances[i], sub, rollout, j, share, convex[i],
                                          int(k))  # fmt: skip
        return [r for r in results if r is not None]

    # -- per instance ---------------------------------------------------------------------
    def _without_rtg(self, convex: WarmStartResult) -> WarmStartResult:
        """The convex warm start failed: no ``J_CVX`` to condition on, nothing to fall back to."""
        record = replace(
            convex.record,
            source="art",
            accepted=False,
            fallback_source=convex.record.source,
            reason=f"no R(t_1) = -J_CVX: the convex warm start failed ({convex.record.reason})",
        )
        return WarmStartResult(None, record, convex.solution)

    def _decide(
        self,
        instance: Any,
        batch: Batch,
        rollout: ArtRollout,
        j: int,
        share: float,
        convex: WarmStartResult | None,
        k: int = 0,
    ) -> WarmStartResult:
        start = time.perf_counter()
        x, u = rollout.x[j], rollout.u[j]
        guess = Trajectory(x=x, u=u, p=np.zeros(0))
        cost = trajectory_cost(guess)
        ctg = self.adapter.trajectory_ctg(instance, batch.models[j], x, u)
        rtg0, ctg0 = float(rollout.rtg[j, 0]), float(rollout.ctg[j, 0])
        details: dict[str, Any] = {
            "art_mode": self.art_mode, "frame": self.frame, "rtg0": rtg0, "ctg0": ctg0,
            "art_cost": cost, "art_constraint_to_go": ctg, "generation_s": share,
            "convex_s": convex.record.time_s if convex else 0.0, "k": k,
        }  # fmt: skip
        if self.acceptance is None:
            decision = Acceptance(True, math.nan, math.nan, "no acceptance check")
        else:
            decision = self.acceptance.evaluate(
                rtg_desired=rtg0, ctg_desired=ctg0, rtg_realized=-cost, ctg_realized=ctg
            )
            details.update(E_R=decision.E_R, E_C=decision.E_C)
        if not decision.accepted:
            convex = convex or self.fallback.guess(instance)
            details["convex_s"] = convex.record.time_s
        elapsed = details["convex_s"] + share + time.perf_counter() - start
        if decision.accepted:
            record = WarmStartRecord(
                source="art",
                time_s=elapsed,
                cost=cost,
                constraint_to_go=ctg,
                reason=decision.reason,
                details=details,
            )
            return WarmStartResult(guess, record, convex.solution if convex else None)
        record = WarmStartRecord(
            source="art",
            time_s=elapsed,
            cost=convex.record.cost,
            constraint_to_go=convex.record.constraint_to_go,
            accepted=False,
            reason=f"rejected: {decision.reason}",
            fallback_source=convex.record.source,
            details=details,
        )
        return WarmStartResult(convex.trajectory, record, convex.solution)
