"""The robust ART paper's experiments (Sec. 5, Figs. 5-10): registered, not implemented yet.

``robust-warmstart`` (PS-CVX/PS-ART, deterministic and chance-constrained, RTN- and
ROE-trained models), ``robust-trajectory`` (the instance with the largest ART gain) and
``robust-posthoc`` (E_R, E_C and the acceptance check) need ART runs trained on a
``robust-rendezvous`` dataset; their runs end with a clear error until they land.
"""

from __future__ import annotations

from pathlib import Path

from scpformer.experiments.runner import RunOptions


def run(options: RunOptions, *, command: str = "", name: str = "robust-warmstart") -> Path:
    """Not implemented yet: a ``ValueError`` naming the experiment."""
    raise ValueError(f"{name}: not implemented yet (issue 13); see `scpformer experiment list`")
