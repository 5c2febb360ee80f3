"""Package trained runs as the shipped pretrained models (slim weights, model card, manifest).

``python -m scpformer.pretrained.package NAME RUN --commands FILE [--out DIR]`` copies the
best-validation checkpoint(s) of ``RUN`` into ``DIR/NAME`` without the training state
(:func:`scpformer.train.checkpoint.slim_checkpoint`), loads the copy with the loader the warm
start uses, writes ``DIR/NAME/MODEL_CARD.md`` (the commands of ``FILE`` that made the data and
the run, the dataset's size and seed from its manifest, training time, test metrics,
parameter count, SHA-256 of each file) and records the checksums in ``DIR/manifest.json``.
``NAME`` is ``art-rendezvous``, ``art-robust``, ``tscvx`` or ``tscvx-midflight``; ``DIR``
defaults to the package's ``scpformer/pretrained``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from scpformer.data.storage import file_sha256
from scpformer.pretrained import (
    GUIDANCE_MODELS,
    MANIFEST_FORMAT,
    MANIFEST_NAME,
    MODEL_FAMILIES,
    PRETRAINED_DIR,
)
from scpformer.train.checkpoint import CHECKPOINT_NAME, checkpoint_path, slim_checkpoint

TSCVX_NETWORKS = ("tight", "solution")
MAX_FILE_BYTES = 5 * 2**20  # "a few MB at most" per shipped file
CARD_NAME = "MODEL_CARD.md"


def is_tscvx(name: str) -> bool:
    """Whether the shipped model ``name`` is a pair of T-SCvx networks (else one ART)."""
    return MODEL_FAMILIES[name] == "pdg6dof"


def best_checkpoint(folder: Path) -> Path:
    """``folder/best.pt`` (best validation loss) when the run wrote one, else its checkpoint."""
    best = folder / "best.pt"
    return best if best.is_file() else checkpoint_path(folder)


def slim_run(name: str, run: Path, out: Path) -> list[Path]:
    """Slim copies of the checkpoint(s) of ``run`` in ``out/name``, loaded back to check them.

    Returns the files written (``checkpoint.pt``, or ``tight/`` and ``solution/`` ones).
    """
    target = out / name
    if is_tscvx(name):
        files = [
            slim_checkpoint(best_checkpoint(run / net), target / net / CHECKPOINT_NAME)
            for net in TSCVX_NETWORKS
        ]
        from scpformer.models.tscvx import load_tscvx_predictor

        load_tscvx_predictor(target)
    else:
        files = [slim_checkpoint(best_checkpoint(run), target / CHECKPOINT_NAME)]
        from scpformer.train.checkpoint import load_checkpoint

        load_checkpoint(target, family=MODEL_FAMILIES[name], kind="art")
    for path in files:
        if path.stat().st_size > MAX_FILE_BYTES:
            raise ValueError(f"{path}: {path.stat().st_size} bytes, above {MAX_FILE_BYTES}")
    return files


def art_test_metrics(model_folder: Path, data: Path) -> dict[str, Any]:
    """Mean training loss (ART paper Eq. 8) of the packaged model on the test split of
    ``data``, with the model's own normalization."""
    import torch

    from scpformer.data.torch_views import ArtSequenceDataset
    from scpformer.train.art import _encoded, read_sequences
    from scpformer.train.checkpoint import load_checkpoint
    from scpformer.train.config import TrainConfig
    from scpformer.train.distributed import World
    from scpformer.train.loop import evaluate

    ckpt = load_checkpoint(model_folder)
    view = ArtSequenceDataset(data, "test", frame=ckpt.frame, normalize=False)
    arrays = read_sequences(view)
    target = int(ckpt.config.to_dict().get("target_dim", 0) or 0) > 0
    tensors = _encoded(arrays, ckpt.normalization, target)
    with torch.no_grad():
        loss, _ = evaluate(
            ckpt.model, tensors, TrainConfig(batch_size=64), World(), torch.device("cpu")
        )
    return {
        "test loss (Eq. 8, normalized)": round(float(loss), 4),
        "test sequences": len(tensors),
        "test instances": len(set(arrays["base_index"].tolist())),
    }


def tscvx_test_metrics(run: Path) -> dict[str, Any]:
    """The headline numbers of ``RUN/metrics_test.json`` (written by ``train tscvx``)."""
    path = run / "metrics_test.json"
    if not path.is_file():
        return {"test metrics": f"none ({path.name} missing)"}
    metrics = json.loads(path.read_text().replace("NaN", "null"))
    tight, solution = metrics["tight"]["overall"], metrics["solution"]
    return {
        "tight rows: accuracy (all-zeros baseline)": (
            f"{tight['accuracy']:.3f} ({tight['all_zeros_accuracy']:.3f})"
        ),
        "tight rows: precision / recall / F1": (
            f"{tight['precision']:.3f} / {tight['recall']:.3f} / {tight['f1']:.3f}"
        ),
        "solution: MSE (standardized)": f"{solution['mse']:.4f}",
        "solution: mean abs. final mass error [U_M]": (
            f"{solution['final_mass_abs_error_mean']:.4f}"
        ),
        "test samples": solution["samples"],
    }


def training_seconds(run: Path, name: str) -> float:
    """Wall time of the training, from ``metrics.csv`` (ART) or ``config.json`` (T-SCvx)."""
    if is_tscvx(name):
        networks = json.loads((run / "config.json").read_text())["networks"]
        return sum(
            float(net.get("train_seconds_this_launch", math.nan)) for net in networks.values()
        )
    with (run / "metrics.csv").open() as fh:
        return sum(float(row["seconds"]) for row in csv.DictReader(fh))


def _parameters(folders: Sequence[Path]) -> int:
    import torch

    total = 0
    for folder in folders:
        state = torch.load(checkpoint_path(folder), map_location="cpu", weights_only=True)
        total += sum(t.numel() for t in state["state_dict"].values())
    return total


def dataset_facts(data: Path) -> dict[str, Any]:
    """Family, size, seed and outcome counts of a dataset, from its manifest."""
    manifest = json.loads((data / "manifest.json").read_text())
    counts = manifest.get("counts", {})
    facts = {
        "family": manifest["family"],
        "samples": counts.get("samples", manifest["n"]),
        "solved": counts.get("solved"),
        "seed": manifest["seed"],
        "manifest sha256": file_sha256(data / "manifest.json"),
    }
    if manifest.get("config", {}).get("mode"):
        facts["mode"] = manifest["config"]["mode"]
    if manifest.get("source"):
        source, transform = manifest["source"], manifest["transform"]["name"]
        facts["augmented from"] = (
            f"{source.get('n')} samples, seed {source.get('seed')} ({transform})"
        )
    return facts


def loaded_by(name: str) -> str:
    """What loads the shipped model ``name`` when no ``--model`` (or ``default``) is given."""
    start = "tscvx" if is_tscvx(name) else "art"
    if name in GUIDANCE_MODELS.values():
        return (f"loaded by the closed-loop re-plans of `scpformer simulate "
                f"{MODEL_FAMILIES[name]} --warmstart {start}|best` (and the "
                f"`mpc-{MODEL_FAMILIES[name]}` experiment) by default")  # fmt: skip
    return f"loaded by `--model default` (or no `--model`) with `--warmstart {start}`"


def model_card(
    name: str, run: Path, files: Sequence[Path], out: Path, commands: Sequence[str]
) -> str:
    """The Markdown model card of a packaged model (see the module docstring)."""
    config = json.loads((run / "config.json").read_text())
    data = Path(config["data"])
    folder = out / name
    nets = [folder / net for net in TSCVX_NETWORKS] if is_tscvx(name) else [folder]
    if is_tscvx(name):
        metrics = tscvx_test_metrics(run)
        seed = config["networks"]["tight"]["train"]["seed"]
    else:
        metrics = art_test_metrics(folder, data)
        seed = config["train"]["seed"]
    lines = [
        f"# {name}: pretrained model card",
        "",
        f"Family `{MODEL_FAMILIES[name]}`; {loaded_by(name)}. Weights only (fp32, no optimizer "
        "or RNG state): they load with the loaders of trained runs but cannot resume "
        "training.",
        "",
        "## How it was made",
        "",
        "```sh",
        *commands,
        "```",
        "",
        "| dataset | value |",
        "|---|---|",
        *[f"| {k} | {v} |" for k, v in dataset_facts(data).items()],
        "",
        "| training | value |",
        "|---|---|",
        f"| preset | {config.get('preset')} |",
        f"| seed | {seed} |",
        f"| training wall time | {training_seconds(run, name) / 60:.1f} min "
        f"({config.get('device')}, {config.get('world_size')} process) |",
        f"| parameters | {_parameters(nets):,} |",
        f"| package version | {config.get('package_version')} |",
        "| packaged from | the best-validation checkpoint (`best.pt`) of the run |",
        "",
        "## Test metrics (the dataset's test split)",
        "",
        "| metric | value |",
        "|---|---|",
        *[f"| {k} | {v} |" for k, v in metrics.items()],
        "",
        "## Files",
        "",
        "| file | bytes | SHA-256 |",
        "|---|---|---|",
        *[f"| {p.relative_to(folder)} | {p.stat().st_size} | {file_sha256(p)} |" for p in files],
        "",
    ]
    return "\n".join(lines)


def update_manifest(out: Path, name: str, files: Sequence[Path]) -> Path:
    """Record the SHA-256 of ``files`` of model ``name`` in ``out/manifest.json``."""
    path = out / MANIFEST_NAME
    manifest = json.loads(path.read_text()) if path.is_file() else {}
    manifest.setdefault("format", MANIFEST_FORMAT)
    manifest.setdefault("format_version", 1)
    models = manifest.setdefault("models", {})
    models[name] = {
        "family": MODEL_FAMILIES[name],
        "files": {str(p.relative_to(out / name)): file_sha256(p) for p in files},
    }
    manifest["models"] = dict(sorted(models.items()))
    path.write_text(json.dumps(manifest, indent=1) + "\n")
    return path


def package(name: str, run: Path, commands: Sequence[str], out: Path = PRETRAINED_DIR) -> Path:
    """Slim ``run`` into ``out/name``, write its card and its manifest entry; return the
    folder."""
    if name not in MODEL_FAMILIES:
        raise ValueError(f"NAME must be one of {sorted(MODEL_FAMILIES)}, got {name!r}")
    if not (run / "config.json").is_file():
        raise ValueError(f"RUN {run}: no config.json (not a training run folder)")
    files = slim_run(name, run, out)
    (out / name / CARD_NAME).write_text(model_card(name, run, files, out, commands))
    update_manifest(out, name, files)
    return out / name


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m scpformer.pretrained.package", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("name", choices=sorted(MODEL_FAMILIES))
    parser.add_argument("run", type=Path, help="the training run folder")
    parser.add_argument(
        "--commands",
        type=Path,
        required=True,
        help="file with the commands that made the data and the run, one a line",
    )
    parser.add_argument("--out", type=Path, default=PRETRAINED_DIR)
    args = parser.parse_args(argv)
    commands = [line for line in args.commands.read_text().splitlines() if line.strip()]
    folder = package(args.name, args.run, commands, args.out)
    for path in sorted(folder.rglob("*")):
        if path.is_file():
            print(f"{path}  {path.stat().st_size} bytes")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
