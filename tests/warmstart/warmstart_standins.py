"""Stand-ins for the contract's sequence model and normalization (ART_CONTRACT.md).

Defined here, in the tests, so that the warm-start package is tested without the models and
training packages: :class:`AffineNormalization` has the ``encode`` / ``decode`` of
``ArtNormalization`` (per-time-step statistics, scales for R and C), and :class:`ReplayModel`
implements ``start`` / ``predict_action`` / ``predict_state`` by replaying known normalized
sequences while recording every token it is fed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch


@dataclass(frozen=True)
class AffineNormalization:
    """Per-time-step standardization of states and actions, scales for R and C."""

    state_mean: np.ndarray  # (T, 6)
    state_std: np.ndarray  # (T, 6)
    action_mean: np.ndarray  # (T, 3)
    action_std: np.ndarray  # (T, 3)
    rtg_scale: float = 0.1
    ctg_scale: float = 10.0
    target_mean: np.ndarray = field(default_factory=lambda: np.zeros(6))
    target_std: np.ndarray = field(default_factory=lambda: np.full(6, 100.0))

    @classmethod
    def random(cls, n_steps: int, seed: int = 0) -> AffineNormalization:
        rng = np.random.default_rng(seed)
        return cls(
            state_mean=rng.normal(0.0, 50.0, (n_steps, 6)),
            state_std=rng.uniform(10.0, 500.0, (n_steps, 6)),
            action_mean=rng.normal(0.0, 1e-3, (n_steps, 3)),
            action_std=rng.uniform(1e-3, 1e-2, (n_steps, 3)),
        )

    def _stats(self, key: str, step: int | None) -> tuple[np.ndarray | float, np.ndarray | float]:
        if key in ("rtg", "ctg"):
            return 0.0, getattr(self, f"{key}_scale")
        mean, std = getattr(self, f"{key}_mean"), getattr(self, f"{key}_std")
        if key == "target" or step is None:
            return mean, std
        return mean[step], std[step]

    def encode(self, key: str, value, step: int | None = None):
        mean, std = self._stats(key, step)
        return (np.asarray(value, dtype=float) - mean) / std

    def decode(self, key: str, value, step: int | None = None):
        mean, std = self._stats(key, step)
        return np.asarray(value, dtype=float) * std + mean


class ReplayModel:
    """Predicts the given normalized actions and next states, and records its input tokens.

    ``actions`` (B, N, 3) and ``states`` (B, N, 6) are normalized; ``predict_state`` after
    step ``k`` returns ``states[:, k + 1]``. Float64 tensors, so that replays are exact.
    """

    def __init__(self, actions: np.ndarray, states: np.ndarray | None = None) -> None:
        self.actions = torch.as_tensor(actions, dtype=torch.float64)
        self.states = None if states is None else torch.as_tensor(states, dtype=torch.float64)
        self.fed: dict[str, list[np.ndarray]] = {}

    def start(self, batch_size: int, target: torch.Tensor | None = None) -> dict:
        assert batch_size == self.actions.shape[0]
        self.fed = {"rtg": [], "ctg": [], "state": [], "action": [], "target": target}
        return {"k": 0}

    def predict_action(self, cache, rtg, ctg, state) -> torch.Tensor:
        for key, value in (("rtg", rtg), ("ctg", ctg), ("state", state)):
            assert value.dtype == torch.float32 and value.shape[0] == self.actions.shape[0]
            self.fed[key].append(value.double().numpy())
        return self.actions[:, cache["k"]]

    def predict_state(self, cache, action) -> torch.Tensor:
        self.fed["action"].append(np.asarray(action))
        cache["k"] += 1
        if self.states is None:
            return torch.zeros(self.actions.shape[0], 6, dtype=torch.float64)
        return self.states[:, cache["k"]]


def replay_model(norm: AffineNormalization, u: np.ndarray, states: np.ndarray | None = None):
    """A :class:`ReplayModel` of physical impulses ``u`` (B, N, 3) [and states (B, N, 6)]."""
    actions = norm.encode("action", u)  # per-step statistics broadcast over (B, N, 3)
    encoded = None if states is None else norm.encode("state", states)
    return ReplayModel(actions, encoded)
