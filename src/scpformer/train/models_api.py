"""The functions of :mod:`scpformer.models` that training and checkpoints call, in one place.

Training never imports the models at module level: :func:`default_models` imports them when a
run starts, and every entry point takes ``models=`` so that another implementation of the same
names (a test's stand-in, the T-SCvx networks) can be passed instead. The names are those of
the ART contract: ``build_model(kind, config)``, ``preset(kind, name, **overrides)``,
``config_from_dict(kind, dict)``, ``ArtNormalization`` (``from_dataset``, ``encode``,
``to_dict``, ``from_dict``) and, optionally, ``TRAIN_DEFAULTS``.
"""

from __future__ import annotations

import importlib
from types import SimpleNamespace
from typing import Any


def default_models() -> Any:
    """:mod:`scpformer.models` with ``ArtNormalization`` at the top level."""
    module = importlib.import_module("scpformer.models")
    normalization = getattr(module, "ArtNormalization", None)
    if normalization is None:
        normalization = importlib.import_module("scpformer.models.normalization").ArtNormalization
    return SimpleNamespace(
        build_model=module.build_model,
        preset=module.preset,
        config_from_dict=module.config_from_dict,
        ArtNormalization=normalization,
        TRAIN_DEFAULTS=_train_defaults(module),
        MODEL_KINDS=getattr(module, "MODEL_KINDS", ("art", "gru", "lstm")),
    )


def _train_defaults(module: Any) -> Any:
    """``TRAIN_DEFAULTS`` of the models package or of its ``art`` module (None if neither)."""
    found = getattr(module, "TRAIN_DEFAULTS", None)
    if found is None:
        found = getattr(importlib.import_module("scpformer.models.art"), "TRAIN_DEFAULTS", None)
    return found


def resolve(models: Any | None) -> Any:
    """``models`` itself, or :func:`default_models` when None."""
    return default_models() if models is None else models
