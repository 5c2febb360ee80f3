"""Output files of the solve and bench commands: checked before solving, written atomically."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from scpformer.files import FIGURE_FORMATS, check_output_file, write_bytes_atomic


def check_solve_outputs(out: Path | None, plot: Path | None, *figures: Path | None) -> None:
    """Refuse ``--out`` and ``--plot`` (and derived figure paths) that cannot be written.

    Raises
    ------
    ValueError
        Naming the flag and the path (see :func:`scpformer.files.check_output_file`), or
        both flags when ``--out`` and a figure would be the same file.
    """
    if out is not None:
        check_output_file(out, "--out")
    if plot is not None:
        for path in (plot, *figures):
            if path is not None:
                check_output_file(path, "--plot", FIGURE_FORMATS)
                if out is not None and Path(path).resolve() == Path(out).resolve():
                    raise ValueError(f"--out and --plot both write {out}; give two file names")


def write_csv(path: Path, fields: Sequence[str], rows: Iterable[dict[str, Any]]) -> None:
    """Write ``rows`` as CSV to ``path`` atomically (a failed write keeps any earlier file)."""
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(fields))
    writer.writeheader()
    writer.writerows(rows)
    write_bytes_atomic(path, text.getvalue().encode())


def print_rows(rows: list[tuple[str, str]]) -> None:
    """A two-column table: each key padded to the longest, then its value."""
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key:<{width}}  {value}")


def timing_rows(timing: Any, model_step: str) -> list[tuple[str, str]]:
    """The wall time of a solve and its parts (``timing``: a ``Timing``); ``model_step`` names
    the time in ``timing.discretization``."""
    return [
        ("wall time", f"{timing.total:.3f} s"),
        (f"  {model_step}", f"{timing.discretization:.3f} s"),
        ("  conic solver", f"{timing.solver:.3f} s"),
        ("  verification", f"{timing.verification:.3f} s"),
        ("  other", f"{timing.other:.3f} s"),
    ]
