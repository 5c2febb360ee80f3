"""benchmarks/robust_art_every_draw.py: its rows, the Eq. 8 summary and its argument checks."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "robust_art_every_draw.py"


def _script():
    spec = importlib.util.spec_from_file_location("robust_art_every_draw", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _row(draw: int, seed: int = 7, digest: str = "a", **art) -> dict:
    run = {"wall_s": 1.0, "status": "converged", "converged": True, "iterations": 5,
           "cost": 2.0, "used": "tpbvp", "accepted": False}  # fmt: skip
    return {"seed": seed, "draw": draw, "model_sha256": digest, "processes": 1,
            "cvx": dict(run), "art": {**run, **art}}  # fmt: skip


def test_read_rows_keeps_one_seed_and_one_model_in_draw_order(tmp_path):
    path = tmp_path / "rows.jsonl"
    rows = [_row(2), _row(0), _row(1, seed=8), _row(1, digest="b"), _row(1)]
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    kept = _script().read_rows(path, 7, "a")
    assert [r["draw"] for r in kept] == [0, 1, 2]
    assert all(r["seed"] == 7 and r["model_sha256"] == "a" for r in kept)
    assert _script().read_rows(tmp_path / "missing.jsonl", 7, "a") == []


def test_check_errors_counts_the_guesses_inside_the_eq8_window(capsys):
    # 100 E_R: -1.5 and 3.5 are the window's edges (inside), 3.6 and -2 outside;
    # E_C: 0 and 2 inside, 3 outside. Inside on both: draws 0 and 1 only.
    errors = [(-0.015, 0.0), (0.035, 2.0), (0.036, 0.0), (0.01, 3.0), (-0.02, 5.0)]
    rows = [_row(i, E_R=e_r, E_C=e_c) for i, (e_r, e_c) in enumerate(errors)]
    rows.append(_row(9))  # a row of an older file, without the errors: left out
    _script().check_errors(rows)
    out = capsys.readouterr().out
    assert "Eq. 8 on 5 guesses" in out
    assert "within [-1.5, 3.5] on 3" in out
    assert "within [0, 2] on 3" in out
    assert "both on 2" in out


def test_check_errors_says_nothing_without_recorded_errors(capsys):
    _script().check_errors([_row(0), _row(1)])
    assert capsys.readouterr().out == ""


def test_bad_counts_are_refused(run_benchmark):
    done = run_benchmark("robust_art_every_draw.py", "--seed", "1", "--workers", "0")
    assert done.returncode == 2
    assert "--workers and --n must be at least 1" in done.stderr
