"""Training configuration: optimizer, schedule and batching, with the ART paper's values.

:class:`TrainConfig` defaults are Table 4 of the ART paper (Appendix): batch size 4, learning
rate 3e-5, gradient-norm clip 1.0, no learning-rate decay, 8 gradient-accumulation steps.
The robust-ART paper (Table 3) uses the same values. :data:`TRAIN_PRESETS` adds ``small``,
sized for two CPU cores (larger batches, no accumulation, a higher learning rate with a cosine
decay). A models package may refine both through ``scpformer.models.TRAIN_DEFAULTS`` (see
:func:`train_config`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from scpformer.validation import check_finite, check_int, shown

SCHEDULES = ("constant", "cosine")
DEVICES = ("auto", "cpu", "cuda")


@dataclass(frozen=True, kw_only=True)
class TrainConfig:
    """How to train (ART paper Table 4 defaults)."""

    epochs: int = 10  # passes over the training split (not given in the papers)
    batch_size: int = 4  # sequences per micro-batch (Table 4)
    lr: float = 3e-5  # AdamW peak learning rate (Table 4)
    weight_decay: float = 0.0  # AdamW decoupled weight decay (the papers' HF default)
    betas: tuple[float, float] = (0.9, 0.999)  # AdamW moment decay rates
    grad_clip: float = 1.0  # max global gradient norm, 0 = no clipping (Table 4)
    accumulation: int = 8  # micro-batches per optimizer step (Table 4)
    warmup_steps: int = 10  # optimizer steps of linear warm-up from 0 to lr
    schedule: str = "constant"  # after warm-up: "constant" (Table 4: no decay) or "cosine"
    min_lr_ratio: float = 0.1  # cosine floor as a fraction of lr
    validation_fraction: float = 0.1  # share of training instances held out if no validation split
    seed: int = 0  # torch, numpy and python seeds; batch order is a function of (seed, epoch)
    device: str = "auto"  # "auto" (cuda when available), "cpu" or "cuda"

    def __post_init__(self) -> None:
        positive = ("epochs", "batch_size", "accumulation")
        for name in positive:
            object.__setattr__(self, name, check_int(name, getattr(self, name), least=1))
        if not 0.0 < self.lr < math.inf:
            raise ValueError(f"lr must be a positive finite number, got {shown(self.lr)}")
        if self.lr > 1.0:  # 1e300 would overflow torch's float32 schedule
            raise ValueError(f"lr must be at most 1, got {shown(self.lr)}")
        if not 0.0 <= self.weight_decay < math.inf:
            raise ValueError(
                f"weight_decay must be a nonnegative finite number, got {shown(self.weight_decay)}"
            )
        if not self.grad_clip >= 0.0:
            raise ValueError(f"grad_clip must be nonnegative, got {shown(self.grad_clip)}")
        if self.warmup_steps < 0:
            raise ValueError(f"warmup_steps must be nonnegative, got {shown(self.warmup_steps)}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule must be one of {SCHEDULES}, got {self.schedule!r}")
        if not 0.0 <= self.min_lr_ratio <= 1.0:
            raise ValueError(f"min_lr_ratio must be in [0, 1], got {shown(self.min_lr_ratio)}")
        if not 0.0 < self.validation_fraction < 1.0:
            raise ValueError(
                f"validation_fraction must be in (0, 1), got {shown(self.validation_fraction)}"
            )
        if self.device not in DEVICES:
            raise ValueError(f"device must be one of {DEVICES}, got {self.device!r}")
        betas = check_finite("betas", self.betas, shape=(2,))
        if not np.all((betas >= 0.0) & (betas < 1.0)):  # AdamW's moment decay rates
            raise ValueError(f"betas must lie in [0, 1), got {shown(tuple(self.betas))}")
        object.__setattr__(self, "betas", tuple(float(b) for b in betas))

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"betas": list(self.betas)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: (tuple(v) if k == "betas" else v) for k, v in data.items() if k in known})


TRAIN_PRESETS: dict[str, TrainConfig] = {
    "paper": TrainConfig(),
    # two CPU cores: 32-sequence batches, one micro-batch per step, a learning rate for a
    # sub-million-parameter model, cosine decay to 10 %
    "small": TrainConfig(
        epochs=20, batch_size=32, lr=1e-3, accumulation=1, warmup_steps=50, schedule="cosine"
    ),
}

_ALIASES = {
    "learning_rate": "lr",
    "grad_norm_clip": "grad_clip",
    "clip": "grad_clip",
    "gradient_accumulation": "accumulation",
    "grad_accumulation": "accumulation",
    "accumulation_steps": "accumulation",
    "warmup": "warmup_steps",
}


def train_config(preset: str, *, model_defaults: Any = None, **overrides: Any) -> TrainConfig:
    """The training configuration of ``preset`` with ``overrides`` (None values ignored).

    ``model_defaults`` is a models package's ``TRAIN_DEFAULTS``: a mapping from preset name to
    a mapping (or an object with ``to_dict()``/dataclass fields) of training values, e.g.
    ``{"paper": {"lr": 3e-5, "grad_clip": 1.0, "accumulation": 8}}``, or one flat mapping of
    the paper's values (applied to ``paper`` only); common aliases such as ``learning_rate``
    and ``grad_accumulation`` are understood, ``lr_decay: None`` means a constant schedule,
    and unknown keys are ignored. Its values override
    :data:`TRAIN_PRESETS`; explicit ``overrides`` override both.
    """
    if preset not in TRAIN_PRESETS:
        raise ValueError(f"preset must be one of {tuple(TRAIN_PRESETS)}, got {preset!r}")
    base = TRAIN_PRESETS[preset].to_dict()
    known = set(base)
    for key, value in _model_defaults(model_defaults, preset).items():
        name = _ALIASES.get(key, key)
        if name == "lr_decay":
            base["schedule"] = "constant" if value in (None, "none", "constant") else str(value)
        elif name in known and name not in ("seed", "device", "epochs"):
            base[name] = value
    base.update({k: v for k, v in overrides.items() if v is not None})
    return TrainConfig.from_dict(base)


def _model_defaults(model_defaults: Any, preset: str) -> Mapping[str, Any]:
    """The models' training values for ``preset``: a per-preset mapping's entry, or a flat
    mapping (the paper's Table 4 values) for ``paper`` only."""
    defaults = _as_mapping(model_defaults) if model_defaults is not None else {}
    if any(name in defaults for name in TRAIN_PRESETS):
        return _as_mapping(defaults.get(preset, {}))
    return defaults if preset == "paper" else {}


def _as_mapping(value: Any) -> Mapping[str, Any]:
    if isinstance(value, Mapping):
        return value
    if hasattr(value, "to_dict"):
        return value.to_dict()
    if dataclasses.is_dataclass(value):
        return dataclasses.asdict(value)
    return {}
