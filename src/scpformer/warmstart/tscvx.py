"""T-SCvx warm start of the 6-DoF problem: the solution network's guess, and Algorithm 2.

``TscvxWarmStart(predictor).guess(instance)`` is the initial guess of Algorithm 2 (its
input line): the predicted ``(x, u, t_f)`` made consistent where cheap
(:func:`~scpformer.problems.pdg6dof.tscvx.consistent_guess`), replaced by the default cold
start (the cubic profile) when the prediction is unusable (wrong shape, NaN) or its penalized
cost J (Eq. 16) is above ``guess_factor`` times the straight line's, ``max(|J|, 1)``
(:class:`~scpformer.problems.pdg6dof.tscvx.TscvxParameters`); as that bound is at least
``guess_factor``, the straight line is evaluated only when the prediction's J exceeds
``guess_factor`` (one discretization, ~6 ms, saved on nearly every solve). Handed to
``scpformer.pdg6dof.solve(..., method="tscvx", warmstart=provider)``, the provider also
supplies the predicted tight rows of T-SCvx
(:func:`~scpformer.problems.pdg6dof.tscvx.solve_tscvx`); with ``method="scvx"`` only its
guess is used.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from scpformer.files import require_model_path
from scpformer.problems.pdg6dof.adapter import PDGProblem, final_mass_cost, penalty
from scpformer.problems.pdg6dof.api import solve
from scpformer.problems.pdg6dof.config import PDGSolverConfig
from scpformer.problems.pdg6dof.constraints import CONSTRAINT_NAMES, constraint_values
from scpformer.problems.pdg6dof.guess import cubic_profile_trajectory, straight_line_trajectory
from scpformer.problems.pdg6dof.instance import PDGInstance
from scpformer.problems.pdg6dof.theta import theta_vector
from scpformer.problems.pdg6dof.tscvx import (
    TscvxParameters,
    TscvxPredictor,
    consistent_guess,
    convex_excess,
)
from scpformer.scp.solution import Solution, Trajectory
from scpformer.scp.warmstart import WarmStartRecord, WarmStartResult, check_instance, timed

TIGHT_BATCH = 8  # iterations whose tight flags are predicted per forward pass (median run: 6-7)


@dataclass(frozen=True)
class TscvxWarmStart:
    """The T-SCvx networks behind the warm-start interface (see the module docstring)."""

    predictor: TscvxPredictor
    params: TscvxParameters = field(default_factory=TscvxParameters)
    config: PDGSolverConfig | None = None  # used by ``guess`` alone (default: n_nodes of the
    # predictor); ``solve`` uses the solve's configuration

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, device: str = "cpu", **kwargs: Any
    ) -> TscvxWarmStart:
        """Load a T-SCvx run folder with :func:`scpformer.models.tscvx.load_tscvx_predictor`
        (named like :meth:`scpformer.warmstart.art.ArtWarmStart.from_checkpoint`).

        A missing or unreadable run is a ``ValueError`` naming it.
        """
        path = require_model_path(path)
        try:
            from scpformer.models.tscvx import load_tscvx_predictor
        except ModuleNotFoundError as err:
            raise ValueError(f"--model {path}: loading T-SCvx runs needs {err.name}") from err
        try:
            predictor = load_tscvx_predictor(path, device=device)
        except Exception as err:  # a corrupt run raises whatever torch/pickle/zip raise
            raise ValueError(f"--model {path}: not a readable T-SCvx run ({err})") from err
        return cls(predictor, **kwargs)

    @classmethod
    def from_run(cls, run_dir: str | Path, device: str = "cpu", **kwargs: Any) -> TscvxWarmStart:
        """Deprecated name of :meth:`from_checkpoint` (warns)."""
        warnings.warn(
            "TscvxWarmStart.from_run is deprecated; use TscvxWarmStart.from_checkpoint",
            DeprecationWarning,
            stacklevel=2,
        )
        return cls.from_checkpoint(run_dir, device=device, **kwargs)

    def guess(self, instance: PDGInstance) -> WarmStartResult:
        config = self.config or PDGSolverConfig(n_nodes=int(self.predictor.n_nodes))
        return self.guess_for(instance, config)

    def guess_for(self, instance: PDGInstance, config: PDGSolverConfig) -> WarmStartResult:
        """The guess under ``config`` (its node count and lambda)."""
        check_instance(instance, PDGInstance, "pdg6dof")
        self._check_nodes(config)
        start = time.perf_counter()

        def fallback() -> Trajectory:  # the default cold start, built only when it is used
            return cubic_profile_trajectory(instance, config.n_nodes)

        try:
            x, u, tf = self.predictor.predict_solution(theta_vector(instance))
            predicted = consistent_guess(
                instance, x, u, tf, config.n_nodes, self.params.thrust_gain
            )
        except ValueError as err:
            return self._result(fallback(), False, f"prediction unusable: {err}", {}, start)
        details = {"J_prediction": penalized_cost(instance, config, predicted)}
        if not details["J_prediction"] <= self.params.guess_factor:  # the bound is at least this
            yardstick = straight_line_trajectory(instance, config.n_nodes)
            details["J_straight_line"] = penalized_cost(instance, config, yardstick)
            bound = self.params.guess_factor * max(abs(details["J_straight_line"]), 1.0)
            if not details["J_prediction"] <= bound:
                reason = f"J of the prediction above {self.params.guess_factor:g} straight lines'"
                return self._result(fallback(), False, reason, details, start)
        return self._result(predicted, True, "J within the bound", details, start)

    def tight(self, instance: PDGInstance) -> Any:
        """``k -> flags (7N,)`` of the rows predicted tight at iteration ``k``.

        The flags of ``TIGHT_BATCH`` iterations from ``k`` on are predicted in one forward pass
        and kept: between conic solves the network's weights have left the CPU caches, and a
        batch-1 pass then takes about 0.9 ms against 0.17 ms when warm (measured in T-SCvx
        runs, one torch thread), so one pass of 8 costs about what two single ones do.
        """
        theta = theta_vector(instance)
        rows = len(CONSTRAINT_NAMES) * int(self.predictor.n_nodes)
        known: dict[int, np.ndarray] = {}

        def flags(k: int) -> np.ndarray:
            if int(k) not in known:
                ks = np.arange(int(k), int(k) + TIGHT_BATCH)
                thetas = np.repeat(theta[None, :], ks.size, axis=0)
                out = np.asarray(self.predictor.predict_tight(thetas, ks), dtype=bool)
                if out.shape != (ks.size, rows):
                    raise ValueError(
                        f"predict_tight gave flags of shape {out.shape}, expected "
                        f"({ks.size}, {rows}) (7 N per iteration)"
                    )
                known.update(zip(ks.tolist(), out, strict=True))
            return known[int(k)]

        return flags

    def solve(
        self, instance: PDGInstance, config: PDGSolverConfig, eta_init: float | None = None
    ) -> Solution:
        """T-SCvx (Algorithm 2) with this provider:
        ``scpformer.pdg6dof.solve(instance, config, method="tscvx", warmstart=self)``;
        ``eta_init`` overrides the initial trust radius of its parameters."""
        provider = self
        if eta_init is not None:
            provider = replace(self, params=replace(self.params, eta_init=eta_init))
        return solve(instance, config, method="tscvx", warmstart=provider)

    def _check_nodes(self, config: PDGSolverConfig) -> None:
        """Refuse a solve on another node count than the model predicts (its rows and nodes
        would not line up)."""
        if int(self.predictor.n_nodes) != config.n_nodes:
            raise ValueError(
                f"the warm start's model predicts N = {int(self.predictor.n_nodes)} nodes, the "
                f"solve has {config.n_nodes} (--n-nodes); train a model for that N"
            )

    @staticmethod
    def _result(
        trajectory: Trajectory, accepted: bool, reason: str, details: dict, start: float
    ) -> WarmStartResult:
        record = WarmStartRecord(
            source="tscvx",
            time_s=0.0,
            cost=final_mass_cost(trajectory),
            constraint_to_go=math.nan,
            accepted=accepted,
            reason=reason,
            fallback_source=None if accepted else "cubic_profile",
            details=details,
        )
        return WarmStartResult(trajectory, timed(record, start))


def penalized_cost(instance: PDGInstance, config: PDGSolverConfig, z: Trajectory) -> float:
    """``J = C + lambda P`` (Eq. 16) of the guess ``z`` on the full nonlinear problem (its
    flow alone: the linearization is the solver's to compute)."""
    defects = PDGProblem(instance, config).flow_defects(z)
    P = penalty(defects, constraint_values(instance, z.x, z.u)) + convex_excess(instance, z)
    return final_mass_cost(z) + config.scvx.lambda_ * P
