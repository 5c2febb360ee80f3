"""The learned ART warm start of the closed-loop rendezvous: the re-plans ``art`` and ``best``.

A decision transformer starts mid-horizon from the history it conditions on (Celestini et al.,
"Transformer-based model predictive control: trajectory optimization via sequence modeling",
IEEE RA-L 9(11), 2024; their ``art_closed_loop``): at a re-plan at node ``k`` the context is
the flown prefix, the states of nodes ``0 .. k-1`` in the model's frame with the impulses
applied there and the reward and constraint tokens recomputed along them, and Algorithm 2
(dynamics in the loop) continues from node ``k`` with the navigation estimate as the state
token (:meth:`scpformer.warmstart.art.ArtWarmStart.guess_batch` with a
:class:`~scpformer.warmstart.art.FlownHistory`; ``R(t_k) = -J_CVX`` of the remaining problem).

What the guidance knows of the flown nodes (:class:`FlownLog`): node 0 is the instance's
initial state, a re-plan node its navigation estimate, and every other node is propagated from
the node before through the instance's linear model (Eq. 10) with the commanded impulse (the
execution error of a burn is not observed on board). These are mean ROE of the whole
problem's nodes, mapped to the model's frame by its ``Psi(t_j)`` as the training data are.

``art`` warm-starts the SCP from ART's guess (the ART paper: no acceptance check for this
family). ``best`` puts ART's guess and the previous plan shifted in time through the robust
ART paper's post hoc check (Eq. 8, :class:`~scpformer.warmstart.art.AcceptanceCheck`) against
the conditioning ``R(t_k) = -J_CVX``, ``C(t_k) = 0`` and starts from the one it prefers
(:func:`~scpformer.warmstart.art.preferred_guess`: accepted first, then fewer keep-out
violations, then the cost nearer ``J_CVX``); the previous plan alone when ART has no guess.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from typing import Any

import numpy as np

from scpformer.problems.rendezvous.constraints import constraint_to_go
from scpformer.problems.rendezvous.linear_model import linear_model
from scpformer.rendezvous import RendezvousInstance, RendezvousSolverConfig, solve
from scpformer.scp.solution import Solution
from scpformer.scp.warmstart import WarmStart, WarmStartResult, trajectory_cost
from scpformer.warmstart.art import AcceptanceCheck, ArtWarmStart, FlownHistory, preferred_guess

#: Warm starts of a re-plan that run the ART model.
LEARNED = ("art", "best")


@lru_cache(maxsize=4)
def art_provider(model: str | None, config: Any, family: str = "rendezvous") -> ArtWarmStart:
    """The ART provider of ``model`` for ``family`` (a training run or checkpoint; None or
    ``default``: the shipped model of the family, checksum verified), loaded once per
    process and configuration (``config`` solves the convex problem of ``J_CVX``; for
    ``robust-rendezvous`` the TPBVP, its passive-safety mode is the provider's)."""
    from scpformer.pretrained import resolve_model

    path = resolve_model(model, family, guidance=True)
    mode = {"mode": config.safety_mode} if family == "robust-rendezvous" else {}
    return ArtWarmStart.from_checkpoint(path, family=family, config=config, **mode)


class FlownLog:
    """What the guidance knows of the nodes flown so far (module docstring), kept re-plan by
    re-plan: the plans flown and the navigation fixes."""

    def __init__(self, instance: RendezvousInstance, open_loop: Solution) -> None:
        self.instance = instance
        self.model = linear_model(instance)
        self.plans: list[tuple[int, Solution]] = [(0, open_loop)]  # (first node, plan)
        self.fixes: dict[int, np.ndarray] = {}

    def history(self, k: int, estimate: np.ndarray, plan: Solution, shift: int) -> FlownHistory:
        """The history of a re-plan at node ``k`` (``plan`` flown since node ``k - shift``);
        records the estimate of node ``k`` for the later re-plans."""
        if self.plans[-1][0] != k - shift:
            self.plans.append((k - shift, plan))
        u = np.zeros((k, 3))
        starts = [s for s, _ in self.plans] + [k]
        for (s, p), end in zip(self.plans, starts[1:], strict=True):
            u[s:end] = p.trajectory.u[: end - s]
        x = np.zeros((k, 6))
        m = self.model
        for j in range(k):
            if j == 0:
                x[j] = self.instance.roe0
            elif j in self.fixes:
                x[j] = self.fixes[j]
            else:
                x[j] = m.Phi[j - 1] @ (x[j - 1] + m.B[j - 1] @ u[j - 1])
        self.fixes[k] = np.asarray(estimate, dtype=float)
        return FlownHistory(self.instance, x, u)


def solve_learned(
    name: str,
    sub: RendezvousInstance,
    history: FlownHistory,
    previous: WarmStart,
    config: RendezvousSolverConfig,
    model: str | None = None,
) -> Solution:
    """The re-plan of ``sub`` from the warm start ``name`` (``art`` or ``best``, module
    docstring); ``previous`` is the last plan shifted to the re-plan's node. The solution's
    ``extras["warmstart"]["used"]`` names the start the SCP began from."""
    if name not in LEARNED:
        raise ValueError(f"learned warm start must be one of {LEARNED}, got {name!r}")
    art = art_provider(model, config).guess(sub, history)
    if name == "art":
        return solve(sub, config, warmstart=art)
    return solve(sub, config, warmstart=_best(sub, art, previous.guess(sub)))


def _best(sub: RendezvousInstance, art: WarmStartResult, prev: WarmStartResult) -> WarmStartResult:
    """Of ART's guess and the previous plan, the one the post hoc check (Eq. 8) prefers."""
    x = prev.trajectory.x
    prev_ctg = float(constraint_to_go(linear_model(sub).rtn(x), sub.scenario)[0])
    prev = replace(prev, record=replace(prev.record, cost=trajectory_cost(prev.trajectory),
                                        constraint_to_go=prev_ctg))  # fmt: skip
    if art.trajectory is None:
        reason = f"best: previous (ART has no guess: {art.record.reason})"
        return replace(prev, record=replace(prev.record, reason=reason))
    details = art.record.details
    chosen, decisions = preferred_guess(
        AcceptanceCheck(), rtg_desired=details["rtg0"], ctg_desired=details["ctg0"],
        candidates={"art": (art.record.cost, art.record.constraint_to_go),
                    "previous": (prev.record.cost, prev_ctg)},
    )  # fmt: skip
    reason = "best: " + "; ".join(f"{n} ({d.reason})" for n, d in decisions.items())
    result = art if chosen == "art" else prev
    record = replace(result.record, reason=reason, time_s=art.record.time_s,
                     details={**details, "best": chosen})  # fmt: skip
    return replace(result, record=record)


def uses_art(config: Any) -> bool:
    """Whether a loop's configuration flies or compares a learned start."""
    return bool({config.warmstart, *config.compare} & set(LEARNED))
