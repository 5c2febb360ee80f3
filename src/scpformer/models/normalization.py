"""One normalization of ART's tokens, shared by training and inference.

States and controls are standardized per time step and element with the statistics of the
training split pooled over every trajectory twin (those :class:`ArtSequenceDataset` computes,
so one physical state has one normalized value); reward-to-go and constraint-to-go are
divided by a scale (their root mean square over the training split), keeping 0 at 0 ("no
cost / no violation left"); the robust target state is standardized per element.

===========  ==============================  ==========================================
key          encode                          statistics
===========  ==============================  ==========================================
``state``    ``(x - mean_k) / std_k``        ``state_mean, state_std`` (N+1, s)
``action``   ``(u - mean_k) / std_k``        ``action_mean, action_std`` (N, a)
``rtg``      ``R / rtg_scale``               RMS of R(t_k) on the training split [m/s]
``ctg``      ``C / ctg_scale``               RMS of C(t_k) on the training split
``target``   ``(g - mean) / std``            ``target_mean, target_std`` (g,)
===========  ==============================  ==========================================

``step=None`` normalizes a whole sequence ``(..., T, d)`` (rows ``0..T-1``); ``step=k`` one
step's value ``(..., d)`` with row ``k`` (generation). Values may be numpy arrays or torch
tensors; the result has the input's type (and dtype and device for tensors).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from scpformer.data.splits import STD_FLOOR
from scpformer.data.torch_views import ArtSequenceDataset
from scpformer.validation import shown

KEYS = ("state", "action", "rtg", "ctg", "target")
_ARRAYS = ("state_mean", "state_std", "action_mean", "action_std", "target_mean", "target_std")


@dataclass(frozen=True, kw_only=True, eq=False)
class ArtNormalization:
    """Statistics that map physical tokens to the model's inputs and back (module docstring)."""

    state_mean: np.ndarray  # (N+1, s) per time step [frame units]
    state_std: np.ndarray  # (N+1, s)
    action_mean: np.ndarray  # (N, a) [m/s]
    action_std: np.ndarray  # (N, a)
    rtg_scale: float  # reward-to-go per normalized unit [m/s]
    ctg_scale: float  # constraint-to-go per normalized unit
    target_mean: np.ndarray | None = None  # (g,) target state [frame units]
    target_std: np.ndarray | None = None  # (g,)
    _tensors: dict = field(default_factory=dict, repr=False)  # torch copies, per dtype/device

    def __post_init__(self) -> None:
        for name in _ARRAYS:
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, np.asarray(value, dtype=np.float64))
        for kind in ("state", "action"):
            mean, std = getattr(self, f"{kind}_mean"), getattr(self, f"{kind}_std")
            if mean.ndim != 2 or mean.shape != std.shape:
                raise ValueError(
                    f"{kind}_mean and {kind}_std must both be (T, d), got {mean.shape} and "
                    f"{std.shape}"
                )
        if (self.target_mean is None) != (self.target_std is None):
            raise ValueError("target_mean and target_std must be given together")
        for name in ("rtg_scale", "ctg_scale"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive number, got {value}")
            object.__setattr__(self, name, value)
        for name in _ARRAYS:
            value = getattr(self, name)
            if value is not None and name.endswith("std") and np.any(value <= 0.0):
                raise ValueError(f"{name} must be positive everywhere")

    # -- encode / decode --------------------------------------------------------------------
    def encode(self, key: str, value: Any, step: int | None = None) -> Any:
        """Physical ``value`` of token ``key`` -> the model's normalized input."""
        shift, scale = self._affine(key, value, step)
        if isinstance(value, torch.Tensor):  # in float64, as the view: std_k may be tiny
            return ((value.double() - shift) / scale).to(value.dtype)
        return (value - shift) / scale

    def decode(self, key: str, value: Any, step: int | None = None) -> Any:
        """Inverse of :meth:`encode`: normalized ``value`` -> physical units."""
        shift, scale = self._affine(key, value, step)
        if isinstance(value, torch.Tensor):
            return (value.double() * scale + shift).to(value.dtype)
        return value * scale + shift

    def _affine(self, key: str, value: Any, step: int | None) -> tuple[Any, Any]:
        """(shift, scale) of ``key`` shaped to broadcast against ``value``."""
        if key in ("rtg", "ctg"):
            return 0.0, getattr(self, f"{key}_scale")
        if key not in KEYS:
            raise ValueError(f"key must be one of {KEYS}, got {key!r}")
        mean, std = getattr(self, f"{key}_mean"), getattr(self, f"{key}_std")
        if mean is None:
            raise ValueError("this normalization has no target statistics (target_mean/std)")
        if key != "target":
            mean, std = self._rows(key, mean, std, value, step)
        if isinstance(value, torch.Tensor):
            return self._tensor(key, step, mean, value), self._tensor(
                f"{key}/std", step, std, value
            )
        return mean, std

    def _rows(
        self, key: str, mean: np.ndarray, std: np.ndarray, value: Any, step: int | None
    ) -> tuple[np.ndarray, np.ndarray]:
        rows = mean.shape[0]
        if step is not None:
            if not isinstance(step, int | np.integer) or not 0 <= step < rows:
                raise ValueError(
                    f"step must be an int in [0, {rows}) for {key!r}, got {shown(step)}"
                )
            return mean[step], std[step]
        if np.ndim(value) < 2 or value.shape[-2] > rows:
            raise ValueError(
                f"{key} sequence must be (..., T, d) with T <= {rows}, got {tuple(value.shape)}"
            )
        t = value.shape[-2]
        return mean[:t], std[:t]

    def _tensor(self, key: str, step: int | None, array: np.ndarray, like: torch.Tensor):
        """``array`` as a float64 tensor on ``like``'s device, cached (generation is hot)."""
        cache_key = (key, step, array.shape, like.device)
        found = self._tensors.get(cache_key)
        if found is None:
            found = torch.as_tensor(array, dtype=torch.float64, device=like.device)
            self._tensors[cache_key] = found
        return found

    # -- serialization ----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (lists and floats); :meth:`from_dict` rebuilds it."""
        out: dict[str, Any] = {"rtg_scale": self.rtg_scale, "ctg_scale": self.ctg_scale}
        for name in _ARRAYS:
            value = getattr(self, name)
            out[name] = None if value is None else value.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ArtNormalization:
        """Inverse of :meth:`to_dict`; ``ValueError`` on missing or unknown keys."""
        known = {f.name for f in dataclasses.fields(cls) if not f.name.startswith("_")}
        unknown = sorted(set(data) - known)
        missing = sorted({"state_mean", "state_std", "action_mean", "action_std"} - set(data))
        if unknown or missing:
            raise ValueError(f"normalization dict: unknown keys {unknown}, missing {missing}")
        return cls(**data)

    @classmethod
    def from_dataset(
        cls, view: ArtSequenceDataset, *, targets: np.ndarray | None = None
    ) -> ArtNormalization:
        """Statistics of the training split of ``view``'s dataset.

        States and controls: the pooled per-time-step statistics the view standardizes with
        (computed here when the view reads raw values, ``normalize=False``). Reward-to-go and
        constraint-to-go: root mean square over the first N steps of every trajectory twin
        the view serves, in the TRAINING split (whatever split ``view`` serves).

        Parameters
        ----------
        view
            An :class:`ArtSequenceDataset` of a dataset with splits.
        targets
            (n, g) target states of the training trajectories (robust ART's fifth modality);
            their per-element mean and std become ``target_mean/target_std``.
        """
        if view.splits is None:
            raise ValueError("the view has no splits: run `scpformer dataset split` first")
        stats = view._stats or view._pooled(view.twins)
        (state_mean, state_std), (action_mean, action_std) = stats["state"], stats["action"]
        state_std = _per_step_floor(state_mean, state_std)
        action_std = _per_step_floor(action_mean, action_std)
        scales = {key: _training_rms(view, key) for key in ("rtg", "ctg")}
        target_mean = target_std = None
        if targets is not None:
            targets = np.asarray(targets, dtype=np.float64)
            if targets.ndim != 2 or not len(targets):
                raise ValueError(f"targets must be (n, g) with n >= 1, got {targets.shape}")
            target_mean, target_std = targets.mean(axis=0), _floored(targets.std(axis=0))
        return cls(
            state_mean=state_mean,
            state_std=state_std,
            action_mean=action_mean,
            action_std=action_std,
            rtg_scale=scales["rtg"],
            ctg_scale=scales["ctg"],
            target_mean=target_mean,
            target_std=target_std,
        )


def _training_rms(view: ArtSequenceDataset, key: str) -> float:
    """RMS of ``key`` (rtg or ctg) over the view's twins in the training split, 1 if ~0."""
    train = view.splits.indices["train"]
    squares, count = 0.0, 0
    for prefix in view.twins:
        ok = view._status_mask(f"{prefix}_status")[train]
        values = view.samples.column(f"{prefix}_{key}")[train[ok], : view.n_steps]
        squares += float(np.sum(values**2))
        count += values.size
    rms = np.sqrt(squares / count) if count else 0.0
    return float(_floored(np.asarray(rms)))


STEP_STD_FLOOR = 0.1  # per-step std >= this fraction of the element's std over all steps


def _per_step_floor(mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    """Per-step std (T, d) floored at ``STEP_STD_FLOOR`` times the element's overall std.

    Some time steps are nearly deterministic across the dataset: the rendezvous coasts
    without impulses between the waypoint and docking, and every trajectory ends at the
    docking state. Their per-step std is ~0 (the dataset's statistics then store 1.0, a
    floor in physical units: 1 m/s per normalized unit of a control), so at inference a
    small normalized error decodes into a huge impulse, and a small state deviation encodes
    into a huge input. The floor is the element's std pooled over all steps (the law of
    total variance over the per-step means and stds), scaled by ``STEP_STD_FLOOR``.
    """
    degenerate = std == 1.0  # the splits' marker of a floored (constant) element
    variance = np.where(degenerate, 0.0, std**2)
    overall = np.sqrt(np.mean(variance + (mean - mean.mean(axis=0)) ** 2, axis=0))  # (d,)
    floor = STEP_STD_FLOOR * _floored(overall)
    return np.maximum(np.where(degenerate, 0.0, std), floor)


def _floored(std: np.ndarray) -> np.ndarray:
    """Std with a constant feature's ~0 replaced by 1 (as :mod:`scpformer.data.splits`)."""
    return np.where(std < STD_FLOOR, 1.0, std)
