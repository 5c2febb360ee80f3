"""Argument types for counts, seeds and durations: argparse names the flag when a value is
refused."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type`` accepting integers ``>= minimum`` (``--n-nominal -1`` is refused)."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be at least {minimum}, got {value}")
        return value

    parse.__name__ = f"integer >= {minimum}"
    return parse


count = int_at_least(0)  # instance counts that may be zero, seeds
positive = int_at_least(1)  # instance counts, workers, shard sizes


def positive_quantity(unit: str) -> Callable[[str], float]:
    """An argparse ``type`` accepting a positive, finite number of ``unit``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number of {unit}, got {text!r}") from None
        if not (math.isfinite(value) and value > 0.0):
            raise argparse.ArgumentTypeError(f"must be positive and finite, got {text}")
        return value

    parse.__name__ = f"positive {unit}"
    return parse


positive_seconds = positive_quantity("seconds")  # time budgets, limits
positive_time_units = positive_quantity("time units")  # nondimensional times (U_T)
