"""Pretrained models shipped in the package, and the checks that guard them.

One folder per model beside this file, each with weights-only checkpoints (the loaders of
:mod:`scpformer.train.checkpoint` read them) and a ``MODEL_CARD.md``; ``manifest.json`` holds
the SHA-256 of every weights file. :func:`default_model` returns the folder of a problem
family's model after checking every file of it against the manifest, so ``--model default``
(or no ``--model`` with ``--warmstart art|tscvx``) never loads a modified file.

====================  ====================  ===============================================
folder                family                loaded by
====================  ====================  ===============================================
``art-rendezvous``    ``rendezvous``        ``--warmstart art`` (ART, RTN frame)
``art-robust``        ``robust-rendezvous`` ``--warmstart art`` (robust ART, chance, ROE)
``tscvx``             ``pdg6dof``           ``--warmstart tscvx`` (``tight/``, ``solution/``)
``tscvx-midflight``   ``pdg6dof``           ``simulate pdg6dof --warmstart tscvx|best``
====================  ====================  ===============================================

A family's closed-loop guidance re-plans from states along the flight, not from the
sampler's initial states; where a model trained on such states is shipped
(:data:`GUIDANCE_MODELS`), ``guidance=True`` selects it (``tscvx-midflight``: T-SCvx trained on
states drawn along optimal descents, ``generate pdg6dof --midflight-nodes``).

``scripts/build_pretrained.sh`` rebuilds them from seeds; ``python -m
scpformer.pretrained.package`` packages trained runs into this layout.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from scpformer.files import require_model_path

PRETRAINED_DIR = Path(__file__).resolve().parent
MANIFEST_NAME = "manifest.json"
MANIFEST_FORMAT = "scpformer.pretrained"
DEFAULT_NAME = "default"  # the --model value that selects the shipped model
#: problem family -> folder of its pretrained model
FAMILY_MODELS = {
    "rendezvous": "art-rendezvous",
    "robust-rendezvous": "art-robust",
    "pdg6dof": "tscvx",
}
#: problem family -> folder of the model its closed-loop re-plans load by default, where it
#: differs from the open-loop one of :data:`FAMILY_MODELS`
GUIDANCE_MODELS = {"pdg6dof": "tscvx-midflight"}
#: every shipped folder -> its problem family
MODEL_FAMILIES = {
    name: family for models in (FAMILY_MODELS, GUIDANCE_MODELS) for family, name in models.items()
}


class PretrainedError(ValueError):
    """A shipped model that is missing, unlisted or does not match its checksum."""


def is_default(model: Path | str | None) -> bool:
    """Whether ``--model`` asks for the shipped model (not given, or ``default``)."""
    return model is None or str(model) == DEFAULT_NAME


def read_manifest(root: Path | None = None) -> dict[str, Any]:
    """``root/manifest.json`` (``PretrainedError`` when missing or not a manifest); ``root``
    defaults to :data:`PRETRAINED_DIR`."""
    root = PRETRAINED_DIR if root is None else root
    path = root / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text())
    except (OSError, ValueError) as err:
        raise PretrainedError(f"pretrained models: cannot read {path} ({err})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != MANIFEST_FORMAT:
        raise PretrainedError(f"pretrained models: {path} is not a pretrained-model manifest")
    return manifest


def verify_model(name: str, root: Path | None = None) -> Path:
    """Check every file of model ``name`` against the manifest's SHA-256; return its folder.

    Raises
    ------
    PretrainedError
        One line naming the file that is missing or differs from its checksum.
    """
    from scpformer.data.storage import file_sha256

    root = PRETRAINED_DIR if root is None else root
    models = read_manifest(root).get("models", {})
    if name not in models:
        raise PretrainedError(f"pretrained model {name!r} is not in {root / MANIFEST_NAME}")
    folder = root / name
    for relative, expected in models[name]["files"].items():
        path = folder / relative
        if not path.is_file():
            raise PretrainedError(f"pretrained model {name}: {path} is missing; reinstall "
                                  "scpformer or run scripts/build_pretrained.sh")  # fmt: skip
        found = file_sha256(path)
        if found != expected:
            raise PretrainedError(
                f"pretrained model {name}: {path} has SHA-256 {found[:16]}..., the manifest "
                f"lists {expected[:16]}... (modified or corrupt; reinstall scpformer or run "
                "scripts/build_pretrained.sh)"
            )
    return folder


def default_model(family: str, root: Path | None = None, *, guidance: bool = False) -> Path:
    """The verified folder of the shipped model of ``family`` (see the module table); with
    ``guidance``, its closed-loop model (:data:`GUIDANCE_MODELS`) where one is shipped."""
    if family not in FAMILY_MODELS:
        raise PretrainedError(
            f"no pretrained model for family {family!r}; shipped: {sorted(FAMILY_MODELS)}"
        )
    models = {**FAMILY_MODELS, **GUIDANCE_MODELS} if guidance else FAMILY_MODELS
    return verify_model(models[family], root)


def resolve_model(model: Path | str | None, family: str, *, guidance: bool = False) -> Path:
    """``--model``: the shipped, verified model of ``family`` when default (``guidance`` as in
    :func:`default_model`), else ``model``."""
    if is_default(model):
        return default_model(family, guidance=guidance)
    return require_model_path(model)


def model_fingerprint(model: Path | str | None, family: str, *, guidance: bool = False) -> str:
    """SHA-256 over the weights files (``*.pt``) of the model ``--model`` selects.

    What a results folder records about its model: ``default`` names whichever model is
    shipped today, so a folder flown before the shipped model is replaced would otherwise
    resume with the new one. The digest covers each file's path relative to the model (a
    run folder or one checkpoint file) and its SHA-256, in sorted order.
    """
    from scpformer.data.storage import file_sha256

    path = resolve_model(model, family, guidance=guidance)
    files = [path] if path.is_file() else sorted(path.rglob("*.pt"))
    if not files:
        raise ValueError(f"--model {path}: no weights file (*.pt) in it")
    digest = hashlib.sha256()
    for file in files:
        relative = file.name if file == path else file.relative_to(path).as_posix()
        digest.update(f"{relative} {file_sha256(file)}\n".encode())
    return digest.hexdigest()
