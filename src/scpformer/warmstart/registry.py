"""The learned warm starts by name: registered with :func:`scpformer.scp.warmstart.register`
so that every family's ``solve`` resolves them without importing this layer.

=====================  ========  =================================================
family                 name      provider
=====================  ========  =================================================
``rendezvous``         ``art``   :class:`~.art.ArtWarmStart`, the pretrained ART model
``robust-rendezvous``  ``art``   :class:`~.art.ArtWarmStart`, the pretrained robust ART model
``pdg6dof``            ``tscvx`` :class:`~.tscvx.TscvxWarmStart`, the pretrained networks
``pdg6dof``            ``kdtree``, ``interp``: the lookup tables; none ships, so the name
                                 alone is refused (``TscvxWarmStart(load_predictor(RUN))``)
=====================  ========  =================================================

The pretrained models (:mod:`scpformer.pretrained`) are checked against their checksums
when a name is resolved, not when this module is imported.
"""

from __future__ import annotations

from typing import Any

from scpformer.scp.warmstart import WarmStart, register

LOOKUP_KINDS = ("kdtree", "interp")


def _art(family: str) -> Any:
    def factory(config: Any) -> WarmStart:
        from scpformer.pretrained import default_model
        from scpformer.warmstart.art import ArtWarmStart

        kwargs: dict[str, Any] = {"family": family, "config": config}
        if family == "robust-rendezvous" and config is not None:
            kwargs["mode"] = config.safety_mode
        return ArtWarmStart.from_checkpoint(default_model(family), **kwargs)

    return factory


def _tscvx(config: Any) -> WarmStart:
    from scpformer.pretrained import default_model
    from scpformer.warmstart.tscvx import TscvxWarmStart

    return TscvxWarmStart.from_checkpoint(default_model("pdg6dof"), config=config)


def _lookup(kind: str) -> Any:
    def factory(config: Any) -> WarmStart:
        raise ValueError(
            f"warmstart {kind!r}: no pretrained {kind} table ships with scpformer; train one "
            f"(`scpformer train {kind}`) and pass TscvxWarmStart(load_predictor(RUN, {kind!r}))"
        )

    return factory


def register_learned() -> None:
    """Register every learned warm start name (idempotent)."""
    register("rendezvous", "art", _art("rendezvous"))
    register("robust-rendezvous", "art", _art("robust-rendezvous"))
    register("pdg6dof", "tscvx", _tscvx)
    for kind in LOOKUP_KINDS:
        register("pdg6dof", kind, _lookup(kind))
