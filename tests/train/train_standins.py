"""Stand-ins for the training tests: a rendezvous-shaped toy family, a tiny model, a normalization.

``ToyRendezvousFamily`` stores what a rendezvous dataset stores for ART (two twins, states in
both frames, impulses, reward- and constraint-to-go) for trajectories of a linear system under
a linear feedback law, so a model can learn them; it solves in microseconds. ``TinyModel`` and
``TinyNormalization`` follow the ART contract's interfaces (``model(batch) -> (pred, loss)``,
``config.to_dict()``, ``from_dataset/encode/to_dict/from_dict``); :data:`STANDIN_MODELS` is the
namespace the trainer's ``models=`` argument takes in place of :mod:`scpformer.models`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn

from scpformer.data.family import Field, SampleResult
from scpformer.data.torch_views import art_twins

N_STEPS = 8
_ROE = np.linalg.qr(np.random.default_rng(0).normal(size=(6, 6)))[0]  # a fixed "frame change"


@dataclass(frozen=True)
class ToyRendezvousFamily:
    """Linear-feedback trajectories stored in the rendezvous schema (twins ``twins``)."""

    name: str = "rendezvous"
    n_steps: int = N_STEPS
    twins: tuple[str, ...] = ("scp", "cvx")
    success_statuses: ClassVar[frozenset[str]] = frozenset({"ok"})

    def config_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def schema(self) -> tuple[Field, ...]:
        n, f64 = self.n_steps, "float64"
        fields = [
            Field(name="theta", dtype=f64, shape=(13,), normalize=True),
            Field(name="t", dtype=f64, shape=(n + 1,)),
        ]
        for p in self.twins:
            fields += [
                Field(name=f"{p}_status", dtype="str"),
                Field(name=f"{p}_roe", dtype=f64, shape=(n + 1, 6), normalize=True),
                Field(name=f"{p}_rtn", dtype=f64, shape=(n + 1, 6), normalize=True),
                Field(name=f"{p}_dv", dtype=f64, shape=(n, 3), normalize=True),
                Field(name=f"{p}_rtg", dtype=f64, shape=(n + 1,)),
                Field(name=f"{p}_ctg", dtype=f64, shape=(n + 1,)),
            ]
        return tuple(fields)

    def versions(self) -> dict[str, str]:
        return {"numpy": np.__version__}

    def warm_up(self) -> None:
        pass

    def sample(self, rng: np.random.Generator) -> np.ndarray:
        return rng.uniform(-1.0, 1.0, size=13)

    def encode_instance(self, instance: np.ndarray) -> dict[str, Any]:
        return {"theta": instance}

    def solve(self, instance: np.ndarray) -> SampleResult:
        fields: dict[str, Any] = {
            "theta": instance,
            "t": np.linspace(0.0, 100.0 * (2.0 + instance[6]), self.n_steps + 1),
        }
        for number, p in enumerate(self.twins):
            rtn, dv = self._trajectory(instance[:6] * 10.0, gain=0.3 + 0.1 * number)
            cost = np.linalg.norm(dv, axis=1)
            fields |= {
                f"{p}_status": "ok",
                f"{p}_rtn": rtn,
                f"{p}_roe": rtn @ _ROE.T,
                f"{p}_dv": dv,
                f"{p}_rtg": -np.concatenate([np.cumsum(cost[::-1])[::-1], [0.0]]),
                f"{p}_ctg": (np.abs(rtn[:, 0]) < 2.0).astype(float)[::-1].cumsum()[::-1],
            }
        return SampleResult("ok", "", fields)

    def _trajectory(self, x0: np.ndarray, gain: float) -> tuple[np.ndarray, np.ndarray]:
        """x_{k+1} = x_k + [v_k; u_k], u_k = -gain (r_k + v_k) (a damped double integrator)."""
        states, impulses = [x0], []
        for _ in range(self.n_steps):
            x = states[-1]
            u = -gain * (x[:3] + x[3:])
            impulses.append(u)
            states.append(np.concatenate([x[:3] + x[3:], x[3:] + u]))
        return np.array(states), np.array(impulses)


# -- model -----------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TinyConfig:
    hidden: int = 16
    context: int = 100
    dropout: float = 0.1
    state_dim: int = 6
    action_dim: int = 3
    target_dim: int = 0

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class TinyModel(nn.Module):
    """Predicts u_k from (R_k, C_k, x_k[, target]) and x_{k+1} from (x_k, u_k); Eq. 8-like loss."""

    def __init__(self, config: TinyConfig) -> None:
        super().__init__()
        self.config = config
        inputs = 2 + config.state_dim + config.target_dim
        self.policy = nn.Sequential(
            nn.Linear(inputs, config.hidden),
            nn.ReLU(),
            nn.Dropout(config.dropout),
            nn.Linear(config.hidden, config.action_dim),
        )
        self.dynamics = nn.Linear(config.state_dim + config.action_dim, config.state_dim)
        self.time = nn.Parameter(torch.zeros(config.context, config.action_dim))

    def forward(self, batch: dict[str, torch.Tensor]) -> tuple[dict, torch.Tensor]:
        state, action = batch["state"], batch["action"]  # (B, T, 6), (B, T, 3)
        tokens = [batch["rtg"], batch["ctg"], state]
        if self.config.target_dim:
            tokens.append(batch["target"][:, None].expand(-1, state.shape[1], -1))
        pred_action = self.policy(torch.cat(tokens, -1)) + self.time[: state.shape[1]]
        pred_state = self.dynamics(torch.cat([state[:, :-1], action[:, :-1]], -1))
        loss = nn.functional.mse_loss(pred_action, action) + nn.functional.mse_loss(
            pred_state, state[:, 1:]
        )
        return {"action": pred_action, "state": pred_state}, loss


KINDS = ("art", "gru", "lstm")
PRESETS = {"small": TinyConfig(hidden=16), "paper": TinyConfig(hidden=32)}


def build_model(kind: str, config: TinyConfig) -> TinyModel:
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    return TinyModel(config)


def preset(kind: str, name: str, **overrides: Any) -> TinyConfig:
    return dataclasses.replace(PRESETS[name], **overrides)


def config_from_dict(kind: str, data: dict[str, Any]) -> TinyConfig:
    return TinyConfig(**data)


# -- normalization ---------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class TinyNormalization:
    """Per-time-step standardization from the view's pooled training statistics."""

    state_mean: np.ndarray  # (T, 6)
    state_std: np.ndarray
    action_mean: np.ndarray  # (T, 3)
    action_std: np.ndarray
    rtg_scale: float
    ctg_scale: float
    target_mean: np.ndarray | None = None  # (6,)
    target_std: np.ndarray | None = None

    @classmethod
    def from_dataset(cls, view: Any, *, targets: np.ndarray | None = None) -> TinyNormalization:
        stats = view._stats or view._pooled(art_twins(view.samples.manifest))
        (state_mean, state_std), (action_mean, action_std) = stats["state"], stats["action"]
        n = view.n_steps
        return cls(
            state_mean=state_mean[:n],
            state_std=state_std[:n],
            action_mean=action_mean,
            action_std=action_std,
            rtg_scale=10.0,
            ctg_scale=float(n),
            target_mean=None if targets is None else targets.mean(axis=0),
            target_std=None if targets is None else targets.std(axis=0) + 1e-9,
        )

    def encode(self, key: str, value: Any, step: int | None = None) -> Any:
        if key in ("rtg", "ctg"):
            return value / getattr(self, f"{key}_scale")
        mean, std = getattr(self, f"{key}_mean"), getattr(self, f"{key}_std")
        if key != "target":
            rows = slice(0, value.shape[-2]) if step is None else step
            mean, std = mean[rows], std[rows]
        return (value - mean) / std

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TinyNormalization:
        return cls(**data)


STANDIN_MODELS = SimpleNamespace(
    build_model=build_model,
    preset=preset,
    config_from_dict=config_from_dict,
    ArtNormalization=TinyNormalization,
    TRAIN_DEFAULTS=None,
    MODEL_KINDS=KINDS,
)
