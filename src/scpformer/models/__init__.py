"""PyTorch models of the learning layer: ART and its GRU/LSTM baselines.

Every kind reads the same token sequence and has the same interface
(:class:`scpformer.models.sequence.TokenSequenceModel`): ``model(batch) -> (predictions,
loss)`` for training, ``start / predict_action / predict_state / feed_action`` for batched
generation with a cache.

=========  ======================================  ===============================
kind       model                                   configuration, presets
=========  ======================================  ===============================
``art``    :class:`scpformer.models.art.ART`       ``ArtConfig``, ``ART_PRESETS``
``gru``    :class:`scpformer.models.rnn.SequenceRNN`  ``RnnConfig``, ``RNN_PRESETS``
``lstm``   :class:`scpformer.models.rnn.SequenceRNN`  ``RnnConfig``, ``RNN_PRESETS``
=========  ======================================  ===============================
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from torch import nn

from scpformer.models.art import ART, ART_PRESETS, ArtConfig
from scpformer.models.rnn import RNN_PRESETS, RnnConfig, SequenceRNN

MODEL_KINDS = ("art", "gru", "lstm")
PRESET_NAMES = ("paper", "small")

ModelConfig = ArtConfig | RnnConfig


def _check_kind(kind: str) -> None:
    if kind not in MODEL_KINDS:
        raise ValueError(f"kind must be one of {MODEL_KINDS}, got {kind!r}")


def preset(kind: str, name: str, **overrides: Any) -> ModelConfig:
    """The ``name`` preset (``paper`` or ``small``) of model ``kind``, with ``overrides``.

    >>> preset("art", "small", target_dim=6).target_dim
    6
    """
    _check_kind(kind)
    if name not in PRESET_NAMES:
        raise ValueError(f"preset must be one of {PRESET_NAMES}, got {name!r}")
    if kind == "art":
        base: ModelConfig = ART_PRESETS[name]
    else:
        if overrides.get("cell", kind) != kind:
            raise ValueError(f"cell {overrides['cell']!r} contradicts kind {kind!r}")
        base = dataclasses.replace(RNN_PRESETS[name], cell=kind)
    return _replace(base, overrides)


def config_from_dict(kind: str, data: Mapping[str, Any]) -> ModelConfig:
    """The configuration of ``kind`` from ``config.to_dict()`` output (unknown keys: error)."""
    _check_kind(kind)
    if kind == "art":
        return _replace(ArtConfig(), data)
    config = _replace(RnnConfig(cell=kind), data)
    if config.cell != kind:
        raise ValueError(f"cell {config.cell!r} contradicts kind {kind!r}")
    return config


def build_model(kind: str, config: ModelConfig) -> nn.Module:
    """A freshly initialized model of ``kind`` with ``config``."""
    _check_kind(kind)
    if kind == "art":
        return ART(config)
    if not isinstance(config, RnnConfig) or config.cell != kind:
        raise TypeError(f"kind {kind!r} needs an RnnConfig with cell={kind!r}, got {config!r}")
    return SequenceRNN(config)


def _replace(config: ModelConfig, changes: Mapping[str, Any]) -> ModelConfig:
    fields = {f.name for f in dataclasses.fields(config)}
    unknown = sorted(set(changes) - fields)
    if unknown:
        raise ValueError(
            f"unknown {type(config).__name__} field(s) {unknown}; known: {sorted(fields)}"
        )
    return dataclasses.replace(config, **changes)


__all__ = [
    "ART",
    "ART_PRESETS",
    "MODEL_KINDS",
    "RNN_PRESETS",
    "ArtConfig",
    "RnnConfig",
    "SequenceRNN",
    "build_model",
    "config_from_dict",
    "preset",
]
