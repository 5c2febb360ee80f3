"""Every ``scpformer`` command: its name, one-line help, description and where its parser is
built.

A command's parser is built only when the command is used: ``scpformer --help`` and
``scpformer solve --help`` list the commands from this table alone, and ``scpformer solve
rendezvous`` builds the rendezvous parser only. The parsers (:mod:`scpformer.cli.parsers`)
import no part of the library; a command's handler, and with it cvxpy, torch, h5py, ..., is
imported when the command runs (:func:`lazy_handler`). The parsers take their ``help=`` and
description from here (:func:`add_command_parser`), so the text lives here once and the
parsers hold the flags.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable, Iterator, Mapping
from typing import Any

#: ``(parent, name) -> (help, "module:function")``; the function adds the parser of ``name``
#: to the parent's subparsers action. Parent ``""`` is the ``scpformer`` command itself.
COMMANDS: dict[tuple[str, str], tuple[str, str]] = {
    ("solve", "pdg6dof"): (
        "6-DoF free-final-time Mars powered descent with SCvx",
        "scpformer.cli.parsers.pdg6dof:add_solve_parser",
    ),
    ("solve", "rendezvous"): (
        "ISS rendezvous in relative orbital elements (ART paper, Problems 1-3)",
        "scpformer.cli.parsers.rendezvous:add_solve_parser",
    ),
    ("solve", "robust-rendezvous"): (
        "passively safe, chance-constrained LEO rendezvous (robust ART, SCvx*)",
        "scpformer.cli.parsers.robust_rendezvous:add_solve_parser",
    ),
    ("bench", "pdg6dof"): (
        "benchmark SCvx on a seeded set of 6-DoF instances",
        "scpformer.cli.parsers.pdg6dof:add_bench_parser",
    ),
    ("bench", "rendezvous"): (
        "benchmark Problems 1-3 on seeded Table 1 instances",
        "scpformer.cli.parsers.rendezvous:add_bench_parser",
    ),
    ("bench", "robust-rendezvous"): (
        "benchmark SCvx* (deterministic and chance) from the convex warm start",
        "scpformer.cli.parsers.robust_rendezvous:add_bench_parser",
    ),
    ("bench", "art"): (
        "time ART trajectory generation (dynamics in the loop), cached vs uncached",
        "scpformer.cli.parsers.bench:add_bench_art_parser",
    ),
    ("bench", "tscvx"): (
        "time T-SCvx network inference (tight flags and solution) at batch 1",
        "scpformer.cli.parsers.bench:add_bench_tscvx_parser",
    ),
    ("", "generate"): (
        "sample, solve and store a dataset of a problem family",
        "scpformer.cli.data:add_generate_parser",
    ),
    ("", "dataset"): (
        "inspect, check, augment and split datasets",
        "scpformer.cli.data:add_dataset_parser",
    ),
    ("", "train"): ("train a model on a dataset", "scpformer.cli.train:add_train_parser"),
    ("", "experiment"): (
        "reproduce a paper table or figure",
        "scpformer.cli.parsers.experiment:add_experiment_parser",
    ),
    ("", "report"): (
        "gather docs/results/*/results.json into docs/RESULTS.md",
        "scpformer.cli.report:add_report_parser",
    ),
    ("", "demo"): (
        "solve three problems with classical and pretrained learned warm starts",
        "scpformer.cli.parsers.demo:add_demo_parser",
    ),
    ("", "export"): (
        "export a run's networks to ONNX and check them against PyTorch",
        "scpformer.cli.export:add_export_parser",
    ),
    ("", "simulate"): (
        "fly a problem family in closed loop (model predictive control) through its truth model",
        "scpformer.cli.parsers.simulate:add_simulate_parser",
    ),
}


#: ``(parent, name) -> description``: the paragraph of ``scpformer PARENT NAME --help`` under its
#: usage line (:func:`add_command_parser`); commands without one list only their sub-commands.
DESCRIPTIONS: dict[tuple[str, str], str] = {
    ("solve", "pdg6dof"): (
        "Solve the 6-DoF minimum-fuel powered descent problem (T-SCvx paper, Eqs. 2-6, Table 1) "
        "with SCvx and verify it by nonlinear propagation."
    ),
    ("solve", "rendezvous"): (
        "Solve Problem 1 (two-point boundary value), 2 (convex: waypoint and approach cone) or 3 "
        "(keep-out ellipsoid, SCP of Section 4) of the ART paper for an ISS rendezvous (Table 1), "
        "and verify it by replaying the impulses through a two-body + J2 propagator."
    ),
    ("solve", "robust-rendezvous"): (
        "Solve the passively safe rendezvous of the robust ART paper (Table 1) with the "
        "three-stage procedure (convex TPBVP -> deterministic collision avoidance -> passive "
        "safety, deterministic or chance-constrained) and SCvx*; optionally verify the chance "
        "constraint by Monte Carlo through a two-body + J2 propagator."
    ),
    ("bench", "pdg6dof"): (
        "Solve a fixed, seeded set of instances from the nominal sub-range and from Table 2; "
        "report wall time, iterations, converged rate and the share of time inside the conic "
        "solver."
    ),
    ("bench", "rendezvous"): (
        "Solve Problems 1, 2 and 3 (the SCP warm-started from Problem 1 or 2) on a seeded set of "
        "instances sampled from Table 1; report wall time (median, p95), SCP iterations, failure "
        "rate, the share of time inside the conic solver and C_CVX(t_1), the constraint-to-go of "
        "the convex solution. Wall times exclude the verification."
    ),
    ("bench", "robust-rendezvous"): (
        "On a seeded set of Table 1 instances, solve the convex TPBVP and, from it, the "
        "passive-safety problem with SCvx* in both modes (PS-CVX-D, PS-CVX-C); report wall time "
        "(median, p95), iterations, infeasibility rate (not converged) and the share of time in "
        "the conic solver. Wall times exclude the final verification."
    ),
    ("bench", "art"): (
        "Generate ART trajectories with the rendezvous dynamics in the loop (Algorithm 2) and "
        "time them: batch 1 with the key-value cache, and without it (full forward at every "
        "step), and the batched throughput with the cache. Random weights of a preset unless "
        "--model gives a trained run."
    ),
    ("bench", "tscvx"): (
        "Time the T-SCvx predictor's calls (raw theta in, numpy out) at batch 1 and at --batch. "
        "Random weights of a preset unless --model gives a trained run."
    ),
    ("", "generate"): (
        "Sample N instances with the family's sampler, solve them on a local process pool (or a "
        "Ray cluster with --ray) and store them as HDF5 shards with a manifest. Re-running the "
        "same command resumes an interrupted run."
    ),
    ("", "report"): (
        "Write one page with, per paper table and figure, the paper's number, ours and the "
        "commands that reproduce ours."
    ),
    ("", "demo"): (
        "The papers' learned warm starts beside the classical ones, in seconds: the ISS "
        "rendezvous (SCP from the convex solution and from ART), the passively safe rendezvous "
        "(PS-CVX and PS-ART) and the 6-DoF Mars landing (SCvx from the cubic profile and T-SCvx), "
        "each solve timed and verified; with --out, one figure per solve."
    ),
    ("", "export"): (
        "Export each network of a training run to ONNX (full-sequence forward, dynamic batch and "
        "sequence axes), run it with onnxruntime and PyTorch on the same inputs and fail when "
        "they differ by more than --tolerance. A run with sub-folders (RUN/tight, RUN/solution) "
        "writes FILE with each sub-folder's name before .onnx."
    ),
}


def command_help(parent: str, name: str) -> str:
    """The one-line help of command ``name`` under ``parent`` (``""``: top level)."""
    return COMMANDS[parent, name][0]


def add_command_parser(
    sub: argparse._SubParsersAction, parent: str, name: str, **kwargs: Any
) -> argparse.ArgumentParser:
    """Add command ``name`` of ``parent`` to ``sub``, with its help from :data:`COMMANDS` and
    its description from :data:`DESCRIPTIONS`; ``kwargs`` (``usage=``, ...) go to
    ``add_parser``."""
    description = DESCRIPTIONS.get((parent, name))
    return sub.add_parser(name, help=command_help(parent, name), description=description, **kwargs)


def lazy_handler(target: str) -> Callable[[argparse.Namespace], int]:
    """A command handler named ``"module:function"``, imported when the command runs."""

    def handler(args: argparse.Namespace) -> int:
        module, function = target.split(":")
        return getattr(importlib.import_module(module), function)(args)

    handler.target = target  # type: ignore[attr-defined]
    return handler


class _Names(Mapping):
    """``choices`` of a :class:`LazySubParsersAction`: every name, built or not, in the order
    they were added; looking a name up builds its parser."""

    def __init__(self, action: LazySubParsersAction) -> None:
        self._action = action

    def __contains__(self, name: object) -> bool:
        return name in self._action._order

    def __iter__(self) -> Iterator[str]:
        return iter(self._action._order)

    def __len__(self) -> int:
        return len(self._action._order)

    def __getitem__(self, name: str) -> argparse.ArgumentParser:
        return self._action.parser(name)


class LazySubParsersAction(argparse._SubParsersAction):
    """Subparsers whose parsers may be registered by name and help, and built on use.

    ``add_lazy_parser(name, help, target)`` lists ``name`` with ``help`` at once;
    ``target`` (``"module:function"``) is imported and called with this action the first
    time ``name`` is parsed (or looked up in ``choices``), and must then call
    ``add_parser(name, help=<the same help>, ...)``.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._order: list[str] = []
        self._lazy: dict[str, tuple[str, str]] = {}
        self.choices = _Names(self)

    def add_lazy_parser(self, name: str, *, help: str, target: str) -> None:
        self._lazy[name] = (help, target)
        self._order.append(name)
        self._choices_actions.append(self._ChoicesPseudoAction(name, (), help))

    def add_parser(self, name: str, **kwargs: Any) -> argparse.ArgumentParser:
        if name in self._lazy:  # the deferred build: its help is listed already
            declared = self._lazy[name][0]
            given = kwargs.pop("help", declared)
            if given != declared:
                raise ValueError(f"command {name!r}: help {given!r} differs from {declared!r}")
        else:
            self._order.append(name)
        return super().add_parser(name, **kwargs)

    def parser(self, name: str) -> argparse.ArgumentParser:
        """The parser of ``name``, built (its module imported) on first use."""
        if name not in self._name_parser_map and name in self._lazy:
            module, function = self._lazy[name][1].split(":")
            getattr(importlib.import_module(module), function)(self)
            if name not in self._name_parser_map:
                raise ValueError(f"{self._lazy[name][1]} did not add the parser of {name!r}")
        return self._name_parser_map[name]

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        if values and values[0] in self._lazy:
            self.parser(values[0])
        super().__call__(parser, namespace, values, option_string)


def add_lazy_commands(action: LazySubParsersAction, parent: str) -> None:
    """Register every command of ``parent`` in :data:`COMMANDS` on ``action``, unbuilt."""
    for (owner, name), (help_text, target) in COMMANDS.items():
        if owner == parent:
            action.add_lazy_parser(name, help=help_text, target=target)
