"""``tscvx-training`` (T-SCvx paper Table 3): the networks' losses, accuracy against the
all-zeros/all-ones baselines, precision and recall of the tight rows, solution MSE."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

from scpformer.experiments import report as rep
from scpformer.experiments.runner import RunOptions
from scpformer.experiments.tscvx.common import comparison_rows, open_tscvx_study, start_report
from scpformer.files import write_text_atomic


def run_training(options: RunOptions, *, command: str = "", name: str) -> Path:
    """Table 3: losses, test accuracy against the baselines, precision/recall, MSE."""
    from scpformer.train.tscvx import evaluate_tscvx

    study = open_tscvx_study(options)
    run_dir = study.runs["tscvx"]
    report = start_report(options, study, name, command, "Table 3")
    metrics = evaluate_tscvx(run_dir, study.data, split="test")
    losses = {net: last_losses(run_dir / net) for net in ("tight", "solution")}
    run_config = run_dir / "config.json"
    stored = json.loads(run_config.read_text()) if run_config.is_file() else {}
    losses["solution"]["thrust_weight"] = float(stored.get("thrust_weight", 1.0))
    params = parameter_counts(run_dir)
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
    tight_loss_note = f"paper: MSE; ours: weighted BCE, epoch {t['best_epoch']} of {t['epochs']}"
    solution_loss_note = f"epoch {s['best_epoch']} of {s['epochs']}" + _thrust_weight_note(
        s.get("thrust_weight", 1.0)
    )
    return comparison_rows(
        [
            ("constraint NN train / validation loss", "0.024 / 0.024",
             f"{rep.fmt(t['train'])} / {rep.fmt(t['val'])}", tight_loss_note),
            ("constraint NN test binary accuracy", "96.45%", f"{100 * tight['accuracy']:.2f}%"),
            ("predict-only-zeros accuracy", "95.95%",
             f"{100 * tight['all_zeros_accuracy']:.2f}%"),
            ("predict-only-ones accuracy", "4.05%", f"{100 * tight['all_ones_accuracy']:.2f}%"),
            ("tight rows: precision / recall", "n/a",
             f"{rep.fmt(tight['precision'])} / {rep.fmt(tight['recall'])}"),
            ("constraint NN parameters", "8.91M", f"{params['tight'] / 1e6:.3g}M"),
            ("solution NN train / validation MSE", "0.975 / 1.092",
             f"{rep.fmt(s['train'])} / {rep.fmt(s['val'])}", solution_loss_note),
            ("solution NN test MSE", "1.040", rep.fmt(solution["mse"])),
            ("solution NN parameters", "9M", f"{params['solution'] / 1e6:.3g}M"),
        ]
    )  # fmt: skip


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
