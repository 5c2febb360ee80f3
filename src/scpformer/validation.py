"""Input validation shared by every configuration and instance dataclass.

Each check raises ``ValueError`` whose message names the offending field, so that a bad
instance file or command-line value fails fast with one clear line (DESIGN.md, invariants).
"""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np


def check_finite(
    name: str,
    value: Any,
    *,
    shape: tuple[int, ...] | None = None,
    nonnegative: bool = False,
) -> np.ndarray:
    """Return ``value`` as a float array after checking shape, finiteness and sign.

    Raises
    ------
    ValueError
        Naming ``name`` when the value is not numeric, has the wrong shape, holds NaN or
        infinity, or is negative while ``nonnegative`` is set.
    """
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numeric, got {value!r}") from None
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if nonnegative and np.any(array < 0.0):
        raise ValueError(f"{name} must be nonnegative, got {value!r}")
    return array


def check_positive(name: str, value: Any) -> float:
    """Return ``value`` as a float after checking that it is a finite positive scalar."""
    number = float(check_finite(name, value, shape=()))
    if number <= 0.0:
        raise ValueError(f"{name} must be positive, got {number}")
    return number


def check_in_range(name: str, value: Any, low: float, high: float) -> float:
    """Return ``value`` as a float after checking ``low <= value <= high``."""
    number = float(check_finite(name, value, shape=()))
    if not low <= number <= high:
        raise ValueError(f"{name} must lie in [{low}, {high}], got {number}")
    return number


def known_fields(cls: type, data: Any, what: str) -> dict[str, Any]:
    """``data`` as a dict after checking it is a mapping of ``cls``'s dataclass fields only.

    Raises ``ValueError`` naming ``what`` and every unknown key.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{what} must be a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - {f.name for f in fields(cls)})
    if unknown:
        raise ValueError(f"unknown {what} field(s): {', '.join(unknown)}")
    return dict(data)


def read_json(path: str | Path, what: str = "instance") -> Any:
    """The JSON value in ``path``; a missing file or malformed JSON is a one-line ``ValueError``."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{what} file not found: {path}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"malformed JSON in {path}: {err}") from None
