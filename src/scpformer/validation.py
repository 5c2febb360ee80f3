"""Input validation shared by every configuration and instance dataclass.

Each check raises ``ValueError`` whose message names the offending field, so that a bad
instance file or command-line value fails fast with one clear line (DESIGN.md, invariants).
"""

from __future__ import annotations

import json
from dataclasses import MISSING, fields
from pathlib import Path
from typing import Any

import numpy as np

_REAL_KINDS = "iuf"  # numpy dtype kinds accepted as real numbers (not bool, complex, str)


class ArgumentTypeError(TypeError, ValueError):
    """A value of the wrong type; a ``TypeError`` that old ``except ValueError`` still catches."""


def shown(value: Any) -> str:
    """``repr(value)`` with numpy scalars and arrays (also inside lists and tuples) written as
    plain Python values: ``-1.0`` and ``[1.0, nan]``, not ``np.float64(-1.0)`` or ``array(...)``,
    so that an error message reads the same whichever type the number came in."""
    if isinstance(value, np.generic | np.ndarray):
        return repr(value.tolist())
    if isinstance(value, list | tuple) and type(value) in (list, tuple):
        items = [shown(v) for v in value]
        if isinstance(value, list):
            return f"[{', '.join(items)}]"
        return f"({items[0]},)" if len(items) == 1 else f"({', '.join(items)})"
    return repr(value)


def shown_as(value: Any, cls: type | tuple[type, ...]) -> str:
    """:func:`shown`, led by the type's name when ``value`` is a numpy value that is not a
    ``cls``: a check that takes Python ints only then reports ``np.int64(5)`` as ``int64 5``,
    not as a bare (valid-looking) ``5``. Other values read as :func:`shown` writes them."""
    if isinstance(value, np.generic | np.ndarray) and not isinstance(value, cls):
        return f"{type(value).__name__} {shown(value)}"
    return shown(value)


def check_type(name: str, value: Any, cls: type | tuple[type, ...]) -> Any:
    """Return ``value`` after checking it is an instance of ``cls``.

    Raises
    ------
    ArgumentTypeError
        Naming ``name``, the expected and the given type.
    """
    if not isinstance(value, cls):
        names = " or ".join(c.__name__ for c in (cls if isinstance(cls, tuple) else (cls,)))
        raise ArgumentTypeError(
            f"{name} must be a {names}, got {type(value).__name__} {shown(value):.60}"
        )
    return value


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` as a bool after checking it is one (``"false"`` is not).

    Raises
    ------
    ArgumentTypeError
        Naming ``name`` when ``value`` is not ``True``/``False`` (numpy bools included).
    """
    if not isinstance(value, bool | np.bool_):
        raise ArgumentTypeError(f"{name} must be true or false, got {shown(value)}")
    return bool(value)


def check_int(name: str, value: Any, least: int | None = None, most: int | None = None) -> int:
    """Return ``value`` as a Python int after checking it is an integer within the bounds.

    Parameters
    ----------
    name
        The field or argument named by the error message.
    value
        A Python int or a numpy integer scalar (``np.int64(3)`` is taken as ``3``). Bools
        (also ``np.bool_``), floats (also ``3.0``), strings, ``None`` and arrays are refused.
    least, most
        Inclusive bounds; ``None`` leaves that side open.

    Returns
    -------
    int
        ``value`` as a plain Python int.

    Raises
    ------
    ArgumentTypeError
        When ``value`` is not an integer; a ``TypeError`` that ``except ValueError`` catches.
    ValueError
        When ``value`` lies outside ``[least, most]``.

    All messages read alike: ``"epochs must be an integer >= 1, got 0"``, ``"... got float
    3.0"``, ``"... got bool True"``; a value of the wrong type is led by its type's name.
    """
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer):
        # a string's or None's repr shows its type; a number's is led by the type's name
        typed = value is not None and not isinstance(value, str)
        shown_value = f"{type(value).__name__} {shown(value)}" if typed else shown(value)
        raise ArgumentTypeError(f"{name} must be {_integer(least, most)}, got {shown_value:.60}")
    number = int(value)
    if (least is not None and number < least) or (most is not None and number > most):
        raise ValueError(f"{name} must be {_integer(least, most)}, got {number}")
    return number


def _integer(least: int | None, most: int | None) -> str:
    """``"an integer"`` with the bounds of :func:`check_int` in words."""
    if least is not None and most is not None:
        return f"an integer from {least} to {most}"
    if least is not None:
        return f"an integer >= {least}"
    if most is not None:
        return f"an integer <= {most}"
    return "an integer"


def check_finite(
    name: str,
    value: Any,
    *,
    shape: tuple[int, ...] | None = None,
    nonnegative: bool = False,
) -> np.ndarray:
    """Return ``value`` as a float array after checking type, shape, finiteness and sign.

    Raises
    ------
    ArgumentTypeError
        Naming ``name`` when the value is not real: a string, bool, complex number or None.
    ValueError
        Naming ``name`` when the value has the wrong shape, holds NaN or infinity, or is
        negative while ``nonnegative`` is set.
    """
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):  # ragged nesting
        raw = np.asarray(None)
    if raw.dtype.kind not in _REAL_KINDS:
        what = "real, not complex" if raw.dtype.kind == "c" else "numeric"
        raise ArgumentTypeError(f"{name} must be {what}, got {shown(value):.80}")
    array = raw.astype(float)
    if shape is not None and array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite, {_offending(value, ~np.isfinite(array))}")
    if nonnegative and np.any(array < 0.0):
        raise ValueError(f"{name} must be nonnegative, {_offending(value, array < 0.0)}")
    return array


def _offending(value: Any, bad: np.ndarray) -> str:
    """``got VALUE`` for a few numbers; for a larger array, how many entries are bad and where
    the first one is (the whole repr of a trajectory would bury the message)."""
    if bad.size <= 8:
        return f"got {shown(value)}"
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    return f"but {int(bad.sum())} of its {bad.size} entries are not (the first at index {first})"


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


def check_interval(name: str, value: Any) -> tuple[float, float]:
    """``(low, high)`` as floats after checking two finite numbers with ``low <= high`` (a
    sampling range); ``ValueError`` naming ``name`` otherwise."""
    low, high = check_finite(name, value, shape=(2,))
    if low > high:
        raise ValueError(f"{name} must satisfy low <= high, got ({low:g}, {high:g})")
    return float(low), float(high)


def check_trajectory(name: str, value: Any, like: Any) -> Any:
    """Return ``value`` after checking it has ``like``'s type and finite ``x``, ``u``, ``p``
    of ``like``'s shapes (a warm start checked against the default initial guess).

    Raises
    ------
    ArgumentTypeError
        When ``value`` is not of ``like``'s type (e.g. a list).
    ValueError
        Naming ``name.x``/``name.u``/``name.p`` on a wrong shape, NaN or infinity.
    """
    check_type(name, value, type(like))
    for part in ("x", "u", "p"):
        check_finite(f"{name}.{part}", getattr(value, part), shape=np.shape(getattr(like, part)))
    return value


def known_fields(cls: type, data: Any, what: str, complete: bool = False) -> dict[str, Any]:
    """``data`` as a dict after checking it is a mapping of ``cls``'s dataclass fields only
    (and, with ``complete``, that it holds every field without a default).

    Raises ``ValueError`` naming ``what`` and every unknown (or missing) key.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{what} must be a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - {f.name for f in fields(cls)})
    if unknown:
        raise ValueError(f"unknown {what} field(s): {', '.join(unknown)}")
    if complete:
        missing = [f.name for f in fields(cls) if f.name not in data and _required(f)]
        if missing:
            raise ValueError(f"{what} lacks field(s): {', '.join(missing)}")
    return dict(data)


def _required(f: Any) -> bool:
    """A dataclass field without a default value or factory."""
    return f.default is MISSING and f.default_factory is MISSING


def read_json(path: str | Path, what: str = "instance") -> Any:
    """The JSON value in ``path``; a missing file or malformed JSON is a one-line ``ValueError``."""
    path = Path(path)
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{what} file not found: {path}") from None
    except IsADirectoryError:
        raise ValueError(f"{what} file {path} is a folder, not a JSON file") from None
    except OSError as err:
        raise ValueError(f"cannot read {what} file {path}: {err.strerror}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"malformed JSON in {path}: {err}") from None
    except RecursionError:
        raise ValueError(f"malformed JSON in {path}: nested too deeply") from None
