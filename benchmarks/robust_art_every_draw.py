"""PS-ART-C against PS-CVX-C on every draw of a fresh seed: failures, iterations, end-to-end time.

Draws ``--n`` chance-constrained instances of the robust sampler (robust ART paper Table 1,
``sample_instances``) with ``--seed`` -- pick a seed no dataset, training run or setting was
chosen on -- and solves each twice with ``scpformer.robust_rendezvous.solve(...,
method="passive_safety")`` at the paper's SCvx* cap (Table 1: 20 solves):

- PS-CVX-C, from the convex TPBVP (``warmstart="tpbvp"``);
- PS-ART-C, from ART's guess with the post hoc check (Eq. 8), which falls back to the TPBVP
  when it rejects the guess (``ArtWarmStart`` with the shipped model, or ``--model RUN``).

Methods alternate which goes first, one torch thread per process, verification on. Each time
is the wall time of the whole call: the TPBVP (ART conditions R(t1) = -J_CVX on it), ART's
generation, the check, every SCvx* solve, the fallback, the final check. A run fails when it
does not end converged and verified (the paper's "infeasible" SCvx* runs: those still
violating passive safety at the cap).

Prints the paired table of :mod:`scpformer.experiments.paired` (solved by both / one /
neither, wall time and iterations per draw faster / tie / slower, cost where both solved),
McNemar's exact test on the failures, the acceptance rate of ART's guess, where its guesses
fall against the check's window (``E_R`` and ``E_C`` of each guess, in the rows) and the
outcome of the accepted draws alone. Rows are appended to ``--out`` (JSON lines) as they
finish, each with the digest of the model's weights; a rerun with the same file and model
skips the draws already in it (another model's rows in the file are kept and left out of the
summary).
``--workers`` runs draws in parallel processes (each single-threaded; both methods of a draw
run in the same process).

Usage: python benchmarks/robust_art_every_draw.py --seed 8675309 --n 400 [--model RUN]
       [--workers 2] [--out robust-art-every-draw.jsonl]
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from scpformer.experiments.paired import Outcomes, exact_sign_test, paired_table
from scpformer.warmstart.art import AcceptanceCheck

COST_TIE = 1e-3  # [m/s] two delta-v totals closer than this tie (SCvx* tolerance scale)
_STATE: dict = {}  # per worker process: the ART provider and the solver configuration


def _setup(model: str | None) -> None:
    import torch

    from scpformer.robust_rendezvous import RobustSolverConfig
    from scpformer.warmstart.art import ArtWarmStart

    torch.set_num_threads(1)
    from scpformer.pretrained import resolve_model

    config = RobustSolverConfig(safety_mode="chance")
    _STATE["config"] = config
    _STATE["art"] = ArtWarmStart.from_checkpoint(
        resolve_model(model, "robust-rendezvous"),
        family="robust-rendezvous",
        mode="chance",
        config=config,
    )
    from scpformer.robust_rendezvous import RobustInstance, solve

    for warmstart in ("tpbvp", _STATE["art"]):  # load, compile: not part of any draw's time
        solve(RobustInstance(), config, method="passive_safety", warmstart=warmstart, verify=False)


def _solve(instance, warmstart) -> dict:
    from scpformer.robust_rendezvous import solve

    start = time.perf_counter()
    try:
        solution = solve(instance, _STATE["config"], method="passive_safety", warmstart=warmstart)
    except (ValueError, RuntimeError) as err:  # a failure is a draw, not a missing row
        return {"wall_s": time.perf_counter() - start, "status": f"error: {err}",
                "converged": False, "iterations": 0, "cost": float("nan"), "used": None,
                "accepted": False}  # fmt: skip
    wall = time.perf_counter() - start
    record = solution.extras.get("warmstart", {})
    check = {
        name: float(value)
        for name, value in record.get("details", {}).items()
        if name in ("E_R", "E_C")
    }  # Eq. 8 errors of ART's guess; the TPBVP has none
    return {
        "wall_s": wall,
        "status": solution.status.value,
        "converged": solution.converged,
        "iterations": int(solution.iterations),
        "cost": float(solution.cost),
        "used": record.get("used"),
        "accepted": record.get("accepted"),
        **check,
    }


def measure_draw(seed: int, n: int, index: int, key: dict) -> dict:
    """Both methods on draw ``index`` of ``seed`` (the instances are redrawn in the worker);
    ``key`` (the model's digest, the process count) goes into the row."""
    from scpformer.robust_rendezvous import sample_instances

    instance = sample_instances(seed, n)[index]
    methods = {"cvx": "tpbvp", "art": _STATE["art"]}
    order = ("cvx", "art") if index % 2 == 0 else ("art", "cvx")
    row = {"seed": seed, "draw": index, **key}
    for name in order:
        row[name] = _solve(instance, methods[name])
    return row


def measure(args: argparse.Namespace, key: dict, done: set[int]) -> None:
    todo = [i for i in range(args.n) if i not in done]
    with (
        ProcessPoolExecutor(args.workers, initializer=_setup, initargs=(args.model,)) as pool,
        args.out.open("a") as fh,
    ):
        futures = [pool.submit(measure_draw, args.seed, args.n, i, key) for i in todo]
        for count, future in enumerate(futures, 1):
            row = future.result()
            fh.write(json.dumps(row) + "\n")
            fh.flush()
            cvx, art = row["cvx"], row["art"]
            print(
                f"[{count}/{len(todo)}] draw {row['draw']}: PS-CVX-C {cvx['status']} "
                f"{cvx['iterations']} it {cvx['wall_s']:.2f} s; PS-ART-C {art['status']} "
                f"{art['iterations']} it {art['wall_s']:.2f} s, used {art['used']}",
                flush=True,
            )


def outcomes(rows: list[dict], method: str) -> Outcomes:
    """One method's results over ``rows`` (a failed run has no cost)."""
    runs = [r[method] for r in rows]
    solved = np.array([r["converged"] for r in runs])
    cost = np.array([r["cost"] for r in runs], dtype=float)
    return Outcomes(
        time=np.array([r["wall_s"] for r in runs]),
        iterations=np.array([r["iterations"] for r in runs]),
        solved=solved,
        cost=np.where(solved, cost, np.nan),
    )


def summarize(rows: list[dict]) -> None:
    art, cvx = outcomes(rows, "art"), outcomes(rows, "cvx")
    print(paired_table("PS-ART-C", art, "PS-CVX-C", cvx, cost_tie=COST_TIE))
    only_art = int((art.solved & ~cvx.solved).sum())
    only_cvx = int((cvx.solved & ~art.solved).sum())
    p = exact_sign_test(only_art, only_cvx)
    print(
        f"\nfailed runs: PS-ART-C {art.n - art.solved.sum()} / {art.n}, PS-CVX-C "
        f"{cvx.n - cvx.solved.sum()} / {cvx.n}; solved only from ART / only from the TPBVP: "
        f"{only_art} / {only_cvx} (McNemar exact p = {p:.3g})"
    )
    accepted = np.array([bool(r["art"]["accepted"]) for r in rows])
    print(f"Eq. 8 check accepted ART's guess on {accepted.sum()} of {len(rows)} draws "
          f"({100 * accepted.mean():.1f}%)")  # fmt: skip
    if accepted.any():
        a, c = (np.flatnonzero(accepted),) * 2
        print(
            f"on the accepted draws: solved {art.solved[a].sum()} from ART, "
            f"{cvx.solved[c].sum()} from the TPBVP; iterations median "
            f"{np.median(art.iterations[a]):g} vs {np.median(cvx.iterations[c]):g}"
        )
    check_errors(rows)
    statuses = {}
    for r in rows:
        key = (r["art"]["status"], r["cvx"]["status"])
        statuses[key] = statuses.get(key, 0) + 1
    print("status pairs (PS-ART-C, PS-CVX-C):", {f"{k[0]}, {k[1]}": v for k, v in statuses.items()})


def check_errors(rows: list[dict]) -> None:
    """Where ART's guesses fall against the Eq. 8 window (rows that record E_R and E_C)."""
    rows = [r["art"] for r in rows if "E_R" in r["art"] and "E_C" in r["art"]]
    if not rows:
        return
    window = AcceptanceCheck()
    (lo, hi), (c_lo, c_hi) = window.e_r_percent, window.e_c
    e_r = np.round(100.0 * np.array([r["E_R"] for r in rows]), 9)  # the check's 100 E_R
    e_c = np.array([r["E_C"] for r in rows])
    ok_r, ok_c = (e_r >= lo) & (e_r <= hi), (e_c >= c_lo) & (e_c <= c_hi)
    p10, p50, p90 = np.percentile(e_r, [10, 50, 90])
    print(
        f"Eq. 8 on {len(rows)} guesses: 100 E_R median {p50:.2f} (10-90%: {p10:.2f} to "
        f"{p90:.2f}), within [{lo:g}, {hi:g}] on {ok_r.sum()}; E_C median {np.median(e_c):g} "
        f"(90%: {np.percentile(e_c, 90):g}), within [{c_lo:g}, {c_hi:g}] on {ok_c.sum()}; "
        f"both on {(ok_r & ok_c).sum()}"
    )


def read_rows(path: Path, seed: int, model_sha256: str) -> list[dict]:
    """The rows of ``path`` measured on ``seed`` with the model of that digest."""
    if not path.exists():
        return []
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    mine = (r for r in rows if r["seed"] == seed and r.get("model_sha256") == model_sha256)
    return sorted(mine, key=lambda r: r["draw"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, required=True, help="sampler seed (a fresh one)")
    parser.add_argument("--n", type=int, default=400, help="draws (default: 400)")
    parser.add_argument("--model", help="robust ART run folder or checkpoint (default: shipped)")
    parser.add_argument("--workers", type=int, default=1, help="processes (default: 1)")
    parser.add_argument("--out", type=Path, default=Path("robust-art-every-draw.jsonl"))
    parser.add_argument("--summary-only", action="store_true", help="only summarize --out")
    args = parser.parse_args()
    if args.workers < 1 or args.n < 1:
        parser.error("--workers and --n must be at least 1")
    from scpformer.pretrained import model_fingerprint

    digest = model_fingerprint(args.model, "robust-rendezvous")
    if not args.summary_only:
        key = {"model_sha256": digest, "processes": args.workers}
        measure(args, key, {r["draw"] for r in read_rows(args.out, args.seed, digest)})
    rows = [r for r in read_rows(args.out, args.seed, digest) if r["draw"] < args.n]
    if not rows:
        raise SystemExit(f"{args.out}: no draw of seed {args.seed} with this --model")
    summarize(rows)
    processes = sorted({r.get("processes") for r in rows}, key=str)
    print(
        f"model sha256 {digest[:16]}...; torch threads per process: 1; processes: "
        f"{', '.join(map(str, processes))}"
    )


if __name__ == "__main__":
    main()
