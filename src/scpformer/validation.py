"""Input validation shared by every configuration and instance dataclass.

Each check raises ``ValueError`` whose message names the offending field, so that a bad
instance file or command-line value fails fast with one clear line (DESIGN.md, invariants).
"""

from __future__ import annotations

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
