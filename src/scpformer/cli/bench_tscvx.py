"""``scpformer bench tscvx``: inference time of the T-SCvx networks through the predictor.

Times the calls the solver makes (:class:`scpformer.models.tscvx.TscvxPredictor`, raw theta
in, numpy out, standardization included): ``predict_tight(theta, k)`` and
``predict_solution(theta)`` at batch 1, and the throughput at ``--batch``. Each number is the
median over ``--repeats`` calls after ``--warmup`` untimed ones (batch-1 calls alternate
between two thetas, so that the predictor's cached standardization of the last theta, which
T-SCvx's per-iteration ``predict_tight`` calls reuse, is not timed; "same theta" times that
reuse), on ``--threads`` torch threads
(one by default, the setting of the project's <= 1 ms goal; the T-SCvx paper reports 4.6-4.9 ms on
its hardware). The predictor is warmed up first (:meth:`TscvxPredictor.warm_up`: batch-1
calls then run through traced networks, as in the T-SCvx studies). Random weights of a preset
unless ``--model`` gives a trained run. torch is imported when the command runs.

The batch-1 cases are also timed with the per-core caches cold (:func:`cache_evictor` runs
between the calls): inside a T-SCvx run each call comes after a conic solve that has pushed
the weights out, and there a batch-1 ``predict_tight`` took about 0.9 ms against 0.17 ms in a
warm loop (measured on the development machine; T-SCvx therefore predicts several
iterations per call, :data:`scpformer.warmstart.tscvx.TIGHT_BATCH`).
"""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from collections.abc import Callable

import numpy as np


def random_predictor(preset_name: str, tokens: str | None, seed: int):
    """A predictor with freshly initialized networks and unit standardization (N = 50)."""
    import torch

    from scpformer.models.tscvx import (
        SOLUTION_KIND,
        TIGHT_KIND,
        TscvxNormalization,
        TscvxPredictor,
        build_model,
        preset,
    )

    torch.manual_seed(seed)
    extra = {"tokens": tokens} if tokens else {}
    tight = build_model(TIGHT_KIND, preset(TIGHT_KIND, preset_name, **extra))
    solution = build_model(SOLUTION_KIND, preset(SOLUTION_KIND, preset_name, **extra))
    n = tight.config.n_nodes
    norm = TscvxNormalization(
        theta_mean=np.zeros(16), theta_std=np.ones(16), x_mean=np.zeros((n, 14)),
        x_std=np.ones((n, 14)), u_mean=np.zeros((n, 3)), u_std=np.ones((n, 3)),
        tf_mean=0.0, tf_std=1.0,
    )  # fmt: skip
    return TscvxPredictor(tight, solution, norm)


def median_seconds(
    call: Callable[[], object],
    repeats: int,
    warmup: int,
    between: Callable[[], object] | None = None,
) -> float:
    """Median wall time of ``call`` over ``repeats`` runs after ``warmup`` untimed ones;
    ``between`` runs untimed before each timed call."""
    for _ in range(warmup):
        call()
    times = []
    for _ in range(repeats):
        if between is not None:
            between()
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


EVICTION_BYTES = 16 * 2**20  # more than the per-core L2 caches of the machines we measure on


def cache_evictor() -> Callable[[], object]:
    """Something to run between calls that pushes the networks' weights out of the per-core
    caches, as a conic solve between two T-SCvx iterations does (one pass of ``+= 1`` over
    ``EVICTION_BYTES``)."""
    scratch = np.zeros(EVICTION_BYTES // 8)

    def evict() -> None:
        np.add(scratch, 1.0, out=scratch)

    return evict


def run_bench(args: argparse.Namespace) -> int:
    import torch

    from scpformer.models.tscvx import load_tscvx_predictor

    for name in ("repeats", "batch", "threads"):
        if getattr(args, name) < 1:
            raise ValueError(f"--{name} must be positive, got {getattr(args, name)}")
    torch.set_num_threads(args.threads)
    if args.model is not None and (args.preset or args.tokens):
        raise ValueError("--preset and --tokens shape random networks; --model gives trained ones")
    if args.model is not None:
        from scpformer.pretrained import resolve_model

        model = resolve_model(args.model, "pdg6dof")  # 'default': the shipped networks
        predictor = load_tscvx_predictor(model)
        source = str(args.model)
    else:
        preset_name = args.preset or "small"
        predictor = random_predictor(preset_name, args.tokens, args.seed)
        source = f"random {preset_name} weights"
    predictor.warm_up()  # batch-1 calls through the traced networks, as a long run makes them
    rng = np.random.default_rng(args.seed)
    mean, std = predictor.normalization.theta_mean, predictor.normalization.theta_std
    theta = mean + std * rng.standard_normal((args.batch, 16))
    ks = rng.integers(1, 20, size=args.batch)
    alternate = itertools.cycle(theta[:2])  # a new theta each call: nothing cached
    cases = {
        "predict_tight, batch 1": lambda: predictor.predict_tight(next(alternate), 3),
        "predict_tight, same theta": lambda: predictor.predict_tight(theta[0], 3),
        "predict_solution, batch 1": lambda: predictor.predict_solution(next(alternate)),
        f"predict_tight, batch {args.batch}": lambda: predictor.predict_tight(theta, ks),
        f"predict_solution, batch {args.batch}": lambda: predictor.predict_solution(theta),
    }
    params = {
        "tight": sum(p.numel() for p in predictor.tight.parameters()),
        "solution": sum(p.numel() for p in predictor.solution.parameters()),
    }
    print(f"T-SCvx inference ({source}; f2 {params['tight']} and f1 {params['solution']} "
          f"parameters, {args.threads} thread(s), median of {args.repeats} calls)")  # fmt: skip
    for label, call in cases.items():
        seconds = median_seconds(call, args.repeats, args.warmup)
        print(f"  {label:<40} {1e3 * seconds:8.3f} ms")
    evict = cache_evictor()  # what a call between two conic solves meets
    for label, call in list(cases.items())[:3]:
        seconds = median_seconds(call, args.repeats, args.warmup, between=evict)
        print(f"  {label + ', caches cold':<40} {1e3 * seconds:8.3f} ms")
    return 0
