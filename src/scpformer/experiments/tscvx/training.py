"""``tscvx-training`` (T-SCvx paper Table 3): the networks' losses, accuracy against the
all-zeros/all-ones baselines, precision and recall of the tight rows, solution MSE."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from scpformer.experiments import report as rep
from scpformer.experiments.runner import (
    RunOptions,
    check_settings,
)
from scpformer.experiments.tscvx.common import (
    PAPER,
    new_report,
    open_tscvx_study,
    study_settings,
)
from scpformer.files import write_text_atomic


def run_training(options: RunOptions, *, command: str = "", name: str) -> Path:
    """Table 3: losses, test accuracy against the baselines, precision/recall, MSE."""
    from scpformer.train.tscvx import evaluate_tscvx

    study = open_tscvx_study(options)
    run_dir = study.runs["tscvx"]
    settings = study_settings(options, study, name)
    check_settings(options.out, settings)
    metrics = evaluate_tscvx(run_dir, study.data, split="test")
    losses = {net: last_losses(run_dir / net) for net in ("tight", "solution")}
    run_config = run_dir / "config.json"
    stored = json.loads(run_config.read_text()) if run_config.is_file() else {}
    losses["solution"]["thrust_weight"] = float(stored.get("thrust_weight", 1.0))
    params = parameter_counts(run_dir)
    report = new_report(name, f"{PAPER} Table 3", command, settings, study)
    report.comparisons = training_comparisons(metrics, losses, params)
    report.sections.append(("Tight rows per constraint (test split)", per_name_table(metrics)))
    write_text_atomic(
        options.out / "metrics_test.json", json.dumps(metrics, indent=1, default=float)
    )
    return report.write(options.out)


def last_losses(folder: Path) -> dict[str, float]:
    """Training and validation loss at the best-validation epoch of ``folder/metrics.csv`` (of
    the last fold's folder below it): the epoch of the delivered ``best.pt``."""
    candidates = sorted(folder.rglob("metrics.csv"))
    records: list[dict[str, str]] = []
    if candidates:
        with candidates[-1].open(newline="") as handle:
            records = list(csv.DictReader(handle))
    if not records:
        return {"train": math.nan, "val": math.nan, "epochs": 0, "best_epoch": 0}
    best = min(records, key=lambda r: float(r["val_loss"]))
    return {"train": float(best["train_loss"]), "val": float(best["val_loss"]),
            "epochs": len(records), "best_epoch": int(best["epoch"])}  # fmt: skip


def parameter_counts(run_dir: Path) -> dict[str, int]:
    """Trainable parameters of each network of a T-SCvx run."""
    from scpformer.models.predictors import load_predictor

    predictor = load_predictor(run_dir, "tscvx")
    return {
        net: sum(p.numel() for p in getattr(predictor, net).parameters())
        for net in ("tight", "solution")
    }


def _thrust_weight_note(weight: float) -> str:
    """How the solution network's training loss differs from the plain MSE of the test row."""
    if weight == 1.0:
        return ""
    return f"; thrust outputs weighted {weight:g}x in training (the test MSE is unweighted)"


def training_comparisons(metrics: dict, losses: dict, params: dict) -> list[rep.Comparison]:
    """Table 3's rows beside ours."""
    tight, solution = metrics["tight"]["overall"], metrics["solution"]
    t, s = losses["tight"], losses["solution"]
    return [
        rep.Comparison(
            quantity="constraint NN train / validation loss",
            paper="0.024 / 0.024",
            ours=f"{rep.fmt(t['train'])} / {rep.fmt(t['val'])}",
            note=f"paper: MSE; ours: weighted BCE, epoch {t['best_epoch']} of {t['epochs']}",
        ),
        rep.Comparison(
            quantity="constraint NN test binary accuracy",
            paper="96.45%",
            ours=f"{100 * tight['accuracy']:.2f}%",
        ),
        rep.Comparison(
            quantity="predict-only-zeros accuracy",
            paper="95.95%",
            ours=f"{100 * tight['all_zeros_accuracy']:.2f}%",
        ),
        rep.Comparison(
            quantity="predict-only-ones accuracy",
            paper="4.05%",
            ours=f"{100 * tight['all_ones_accuracy']:.2f}%",
        ),
        rep.Comparison(
            quantity="tight rows: precision / recall",
            paper="n/a",
            ours=f"{rep.fmt(tight['precision'])} / {rep.fmt(tight['recall'])}",
        ),
        rep.Comparison(
            quantity="constraint NN parameters", paper="8.91M", ours=f"{params['tight'] / 1e6:.3g}M"
        ),
        rep.Comparison(
            quantity="solution NN train / validation MSE",
            paper="0.975 / 1.092",
            ours=f"{rep.fmt(s['train'])} / {rep.fmt(s['val'])}",
            note=f"epoch {s['best_epoch']} of {s['epochs']}"
            + _thrust_weight_note(s.get("thrust_weight", 1.0)),
        ),
        rep.Comparison(
            quantity="solution NN test MSE", paper="1.040", ours=rep.fmt(solution["mse"])
        ),
        rep.Comparison(
            quantity="solution NN parameters", paper="9M", ours=f"{params['solution'] / 1e6:.3g}M"
        ),
    ]


def per_name_table(metrics: dict) -> str:
    """Accuracy, baselines, precision and recall of the tight rows per constraint name."""
    rows = []
    for name, s in {"all": metrics["tight"]["overall"], **metrics["tight"]["per_name"]}.items():
        rows.append(
            (
                name,
                f"{s['tight_share']:.2%}",
                f"{s['accuracy']:.2%}",
                f"{s['all_zeros_accuracy']:.2%}",
                rep.fmt(s["precision"]),
                rep.fmt(s["recall"]),
            )
        )
    header = ("rows", "tight share", "accuracy", "all-zeros accuracy", "precision", "recall")
    items = metrics["tight"]["items"]
    return f"{items} test (instance, k) items.\n\n" + rep.markdown_table(header, rows)
