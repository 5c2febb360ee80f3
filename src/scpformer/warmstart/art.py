"""ART warm starts: Algorithms 1-2 of the ART paper, the post hoc check of the robust paper.

Generation (ART paper, Sec. 3, Algorithms 1 and 2; robust paper, Sec. 3, "Inference"). With
the sequence model's inference interface (``start``, ``predict_action``, ``predict_state``,
see ``ART_CONTRACT.md``), every instance of a batch starts from its initial state ``x(t_1)``,
the desired reward-to-go ``R(t_1)`` and constraint-to-go ``C(t_1)``; at each step ``k``:

1. the model predicts ``u_k`` from the tokens ``R(t_k), C(t_k), x_k`` (one call);
2. ``R(t_{k+1}) = R(t_k) - (-|u_k|_2)`` and ``C(t_{k+1}) = C(t_k) - C_k`` (Eqs. 4-5), with
   ``C_k`` the instantaneous constraint violation of the family (ART Eq. 21: keep-out zone;
   robust Eq. 7: passive safety with the chance margin) at ``(x_k, u_k)``;
3. the next state is ``x_{k+1} = Phi_k (x_k + B_k u_k)`` (Algorithm 2, dynamics in the loop:
   the family's exact STM and control input matrix) or the model's prediction at the ``u_k``
   token (Algorithm 1, transformer only).

Signs follow the dataset (:func:`scpformer.problems.rendezvous.constraints.reward_to_go`):
``R(t_k) = -sum_{j >= k} |dv_j|_2 <= 0``, so the update adds ``|u_k|`` and the default
``R(t_1) = -J_CVX`` (the cost of the convex warm start: Problem 2 for the rendezvous, the
TPBVP for the robust family) is negative; ``C(t_1) = 0`` by default (both papers).

States are fed in the model's frame (``rtn``: ``Psi_k x_k``, ART Eq. 9; ``roe``: ``x_k``) and
the returned guess is always in the solvers' scaled mean ROE. Algorithm 1 outputs N states
``x_0 .. x_{N-1}``; the final node ``x_N`` (outside the model's N-step context) is propagated
from ``x_{N-1}`` through the STM in both modes.

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
        ``R(t_1)`` (<= 0, [m/s]) and ``C(t_1)`` of each instance, (B,).
    """
    import torch

    start = time.perf_counter()
    n, size = batch.n_steps, batch.x0.shape[0]
    _check_choice("frame", frame, ART_FRAMES)
    _check_choice("art_mode", art_mode, ART_MODES)
    for name, value in (("rtg0", rtg0), ("ctg0", ctg0)):
        if np.shape(value) != (size,) or not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be finite with shape ({size},), got {np.shape(value)}")
    _check_context(model, n)
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
        for k in range(n):
            rtg[:, k], ctg[:, k] = R, C
            u_norm = model.predict_action(
                cache,
                tensor(normalization.encode("rtg", R[:, None], step=k)),
                tensor(normalization.encode("ctg", C[:, None], step=k)),
                tensor(normalization.encode("state", states[:, k], step=k)),
            )  # (B, 3)
            u[:, k] = normalization.decode("action", numpy(u_norm), step=k)
            violations[:, k] = family.violations(batch, k, x[:, k], u[:, k])
            R = R + np.linalg.norm(u[:, k], axis=1)  # R(t_{k+1}) = R(t_k) - (-|u_k|)
            C = C - violations[:, k]
            x_next = batch.step(k, x[:, k], u[:, k])
            if k == n - 1:
                x[:, n] = x_next
                break
            if art_mode == "transformer":
                predicted = model.predict_state(cache, u_norm)  # feeds the u_k token
                states[:, k + 1] = normalization.decode("state", numpy(predicted), step=k + 1)
                x[:, k + 1] = batch.from_frame(k + 1, states[:, k + 1], frame)
            else:
                feed_action(cache, u_norm)
                x[:, k + 1] = x_next
                states[:, k + 1] = batch.to_frame(k + 1, x_next, frame)
    return ArtRollout(x, u, states, rtg, ctg, violations, time.perf_counter() - start)


# ======================================================================================
# the provider
# ======================================================================================
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
        Solver configuration of the convex warm start (``J_CVX`` and the fallback).
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
        self.adapter = art_family(family, mode)
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
    def guess(self, instance: Any) -> WarmStartResult:
        """ART's guess for one instance (see :meth:`guess_batch`)."""
        return self.guess_batch([instance])[0]

    def guess_batch(self, instances: Sequence[Any]) -> list[WarmStartResult]:
        """ART's guesses for many instances, generated as one batch through the model.

        Each result's record gives ``source="art"``, the total time (convex warm start, when
        solved, plus this instance's share of the batched generation), the cost and
        ``C(t_1)`` of the returned guess, the acceptance decision and, when rejected, the
        fallback. ``details`` holds ``R(t_1)``, ``C(t_1)``, ``E_R``, ``E_C`` and ART's own
        cost and constraint-to-go.
        """
        if not instances:
            return []
        batch = self.adapter.batch(instances)
        convex: list[WarmStartResult | None] = [None] * len(instances)
        if self.rtg is None:
            convex = [self.fallback.guess(instance) for instance in instances]
        rtg0 = np.array([self.rtg if c is None else -c.record.cost for c in convex], dtype=float)
        ok = np.flatnonzero(np.isfinite(rtg0))
        results: list[WarmStartResult | None] = [None] * len(instances)
        for i in np.flatnonzero(~np.isfinite(rtg0)):
            results[i] = self._without_rtg(convex[i])
        if ok.size:
            sub = batch if ok.size == len(instances) else self.adapter.batch(
                [instances[i] for i in ok])  # fmt: skip
            rollout = generate(self.model, self.normalization, sub, self.adapter,
                               frame=self.frame, art_mode=self.art_mode, rtg0=rtg0[ok],
                               ctg0=np.full(ok.size, self.ctg))  # fmt: skip
            share = rollout.time_s / ok.size
            for j, i in enumerate(ok):
                results[i] = self._decide(instances[i], sub, rollout, j, share, convex[i])
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
            "convex_s": convex.record.time_s if convex else 0.0,
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
