"""Load any T-SCvx predictor from its run folder: the networks or a lookup table.

Every predictor answers the same API (``n_nodes``, ``predict_tight``,
``predict_tight_proba``, ``predict_solution``; raw theta in), so T-SCvx
(:class:`scpformer.warmstart.tscvx.TscvxWarmStart`) and the experiments take any of them:

=========  ==========================================  ======================================
kind       made by                                     run folder holds
=========  ==========================================  ======================================
tscvx      ``scpformer train tscvx``                   ``tight/``, ``solution/`` checkpoints
kdtree     ``scpformer train kdtree``                  ``lookup.json``, ``lookup.npz``
interp     ``scpformer train interp``                  ``lookup.json``, ``lookup.npz``
=========  ==========================================  ======================================
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

PREDICTOR_KINDS = ("tscvx", "kdtree", "interp")


def predictor_kind(run_dir: Path | str) -> str:
    """The kind of the predictor in ``run_dir`` (``ValueError`` when it holds none)."""
    run = Path(run_dir)
    if not run.is_dir():
        raise ValueError(f"--model {run}: no such run folder")
    lookup = run / "lookup.json"
    if lookup.is_file():
        try:
            kind = json.loads(lookup.read_text()).get("kind")
        except (ValueError, AttributeError):
            raise ValueError(f"--model {run}: {lookup.name} is corrupt") from None
        if kind not in PREDICTOR_KINDS:
            raise ValueError(f"--model {run}: unknown lookup kind {kind!r}")
        return str(kind)
    if (run / "tight").is_dir() or (run / "solution").is_dir():
        return "tscvx"
    raise ValueError(
        f"--model {run}: not a T-SCvx run (no tight/ and solution/) nor a lookup table "
        "(no lookup.json); make one with `scpformer train tscvx|kdtree|interp`"
    )


def load_predictor(run_dir: Path | str, kind: str | None = None, device: str = "cpu") -> Any:
    """The predictor of ``run_dir``; ``kind`` (checked when given) is read from the folder.

    Raises
    ------
    ValueError
        Naming the run when it is missing, of another kind, or unreadable.
    """
    found = predictor_kind(run_dir)
    if kind is not None and kind != found:
        raise ValueError(f"--model {run_dir}: a {found} run, not {kind}")
    try:
        if found == "tscvx":
            from scpformer.models.tscvx import load_tscvx_predictor

            return load_tscvx_predictor(run_dir, device=device)
        from scpformer.models.lookup import load_lookup_predictor

        return load_lookup_predictor(run_dir)
    except ValueError:
        raise
    except Exception as err:  # a corrupt file raises whatever torch, zip or numpy raise
        first = (str(err).splitlines() or [type(err).__name__])[0][:200]
        raise ValueError(f"--model {run_dir}: not a readable {found} run ({first})") from None
