"""Flags of ``scpformer simulate rendezvous|pdg6dof|robust-rendezvous``
(handler: :mod:`scpformer.cli.simulate`).

Built without importing the library: the choices are spelled here and checked against
:mod:`scpformer.guidance` by the tests.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scpformer.cli.argtypes import count, positive, positive_seconds, positive_time_units
from scpformer.cli.commands import command_help, lazy_handler
from scpformer.cli.dataclass_args import with_default

WARMSTARTS = ("cold", "previous", "art", "best")  # scpformer.guidance.WARMSTARTS
#: scpformer.guidance.robust_rendezvous_mpc.WARMSTARTS
ROBUST_WARMSTARTS = ("cold", "previous", "art", "best")
INSTANCES = ("default", "sampled")  # scpformer.guidance.campaign.INSTANCES
ERRORS = ("table2", "none")
PDG_WARMSTARTS = ("cold", "previous", "tscvx", "best")  # scpformer.guidance.pdg6dof_mpc.WARMSTARTS
PDG_ERRORS = ("default", "none")
PDG_TRACKING = ("lqr", "none")


def add_simulate_parser(commands: argparse._SubParsersAction) -> None:
    """Register ``simulate rendezvous``, ``simulate pdg6dof`` and ``simulate
    robust-rendezvous`` on the top-level subparsers."""
    simulate = commands.add_parser("simulate", help=command_help("", "simulate"))
    families = simulate.add_subparsers(dest="family", required=True, metavar="FAMILY")
    _add_rendezvous(
        families,
        "rendezvous",
        "shrinking-horizon MPC of the ISS rendezvous through the two-body + J2 truth",
        "Fly the rendezvous in closed loop: re-plan Problem 3 every K impulses from a "
        "navigation estimate and apply the plan through the truth model with navigation, "
        "actuation and process errors (robust ART paper, Table 2).",
        WARMSTARTS,
        "warm start of each re-plan: cold (the convex Problem 2), previous (the last "
        "accepted plan shifted in time), art (the ART model of --model started from node k, "
        "its context the flown prefix) or best (art or previous, the one the post hoc check "
        "of Eq. 8 prefers)",
    )
    _add_pdg6dof(families)
    _add_rendezvous(
        families,
        "robust-rendezvous",
        "shrinking-horizon MPC of the chance-constrained, passively safe rendezvous",
        "Fly the chance-constrained, passively safe rendezvous (robust ART paper) in closed "
        "loop: re-solve the remaining problem every K impulses from a navigation estimate and "
        "apply the plan through the two-body + J2 truth with the Table 2 navigation, "
        "actuation and process errors; success needs the pre-docking state reached and no "
        "keep-out or passive-safety violation (dense Monte Carlo) along the flown trajectory.",
        ROBUST_WARMSTARTS,
        "warm start of each re-plan: cold (the three-stage solve), previous (passive "
        "safety from the last accepted plan shifted in time), art (passive safety from the "
        "robust ART model of --model started from node k, its context the flown prefix; the "
        "Eq. 8 check falls back to the TPBVP) or best (passive safety from art's guess or "
        "the shifted plan, the one the Eq. 8 check prefers; the TPBVP when it accepts "
        "neither)",
    )


def _add_rendezvous(
    families: argparse._SubParsersAction,
    name: str,
    summary: str,
    description: str,
    warmstarts: tuple[str, ...],
    warmstart_help: str,
) -> None:
    """A rendezvous family's parser (``rendezvous``, ``robust-rendezvous``): the same flags,
    their own warm starts and texts."""
    parser = families.add_parser(
        name,
        help=summary,
        description=(
            f"{description} Writes DIR/runs.csv (one row per run; a rerun resumes), "
            "DIR/run-NNNN.npz and DIR/simulate.png."
        ),
    )
    _add_loop_arguments(
        parser,
        warmstarts,
        warmstart_help,
        replan_every=(10, "impulses flown between re-plans"),
        seed="seed of the errors (and sampled instances)",
    )
    _add_instances_argument(
        parser,
        "default: every run flies the Table 1 default instance; sampled: one sampled Table 1 "
        "instance per run",
    )
    parser.add_argument(
        "--errors",
        choices=ERRORS,
        default="table2",
        help=with_default("navigation, actuation and process errors: table2 or none", "table2"),
    )
    if name == "robust-rendezvous":
        parser.add_argument(
            "--mission-risk",
            type=float,
            metavar="EPSILON",
            help=with_default(
                "design every flight for a chance EPSILON that any node's drift enters its "
                "ellipsoid: each of the N nodes' chance constraints then uses Delta = "
                "EPSILON / N (Boole's inequality); without it, the instance's Delta per node",
                "1e-3 per node",
            ),
        )
        parser.add_argument(
            "--covariance",
            choices=("loop", "eq14"),
            default="loop",
            help=with_default(
                "covariance the chance constraints design for: loop, a navigation fix at each "
                "re-plan only, the dispersion growing in between as the loop flies; eq14, a "
                "fix before every maneuver (the paper's Eq. 14)",
                "loop",
            ),
        )
    if "art" in warmstarts:
        parser.add_argument(
            "--model",
            type=Path,
            metavar="RUN",
            help=with_default(
                "ART model of --warmstart/--compare art (or best): a training run folder or "
                "checkpoint file, or 'default': the pretrained model shipped with scpformer",
                "default",
            ),
        )
    _add_run_arguments(parser)


def _add_pdg6dof(families: argparse._SubParsersAction) -> None:
    parser = families.add_parser(
        "pdg6dof",
        help="re-planned free-final-time SCvx of the 6-DoF Mars landing through the truth model",
        description=(
            "Fly the 6-DoF powered descent in closed loop: every K intervals of the current "
            "plan, re-solve the free-final-time problem from a navigation estimate and apply "
            "the plan's first-order-hold thrust through the truth model with thrust magnitude "
            "and pointing errors, mass, inertia and aerodynamic mismatch and an initial-state "
            "dispersion per run. Writes DIR/runs.csv (one row "
            "per run; a rerun resumes), DIR/run-NNNN.npz and DIR/simulate.png."
        ),
    )
    _add_loop_arguments(
        parser,
        PDG_WARMSTARTS,
        "warm start of each re-plan: cold (SCvx from the cubic profile), previous (SCvx "
        "from the last accepted plan shifted in time and re-timed), tscvx (T-SCvx with "
        "the shipped networks at the current state) or best (tscvx or previous, the one "
        "whose guess has the lower penalized cost J of Eq. 16)",
        replan_every=(5, "intervals of the current plan flown between re-plans"),
        seed="seed of the errors, dispersions (and sampled instances)",
    )
    _add_instances_argument(
        parser,
        "default: the Table 1 instance with a dispersed initial state per run; sampled: one "
        "instance of the nominal sampler per run",
    )
    parser.add_argument(
        "--errors",
        choices=PDG_ERRORS,
        default="default",
        help=with_default(
            "default: thrust 1%% and 0.1 deg, mass 1%%, inertia 5%%, aerodynamic coefficient "
            "20%%, navigation and initial dispersion (1 sigma); none: no error",
            "default",
        ),
    )
    parser.add_argument(
        "--tracking",
        choices=PDG_TRACKING,
        default="lqr",
        help=with_default(
            "lqr: a time-varying LQR on the plan's linearization corrects the thrust every "
            "interval from a navigation fix; none: the plan's thrust is flown open loop "
            "between re-plans",
            "lqr",
        ),
    )
    parser.add_argument(
        "--replan-iter-max",
        type=positive,
        default=None,
        metavar="N",
        help="conic solves a re-plan may take; a capped re-plan ends unconverged (flown if "
        "verified, else the last plan flies on) and a capped T-SCvx re-plan has no cold "
        "fallback (default: the solver's cap, 100)",
    )
    parser.add_argument(
        "--min-remaining-time",
        type=positive_time_units,
        default=1.0,
        metavar="T",
        help=with_default("no re-plan when less than T U_T of the plan remain", 1.0),
    )
    parser.add_argument(
        "--model",
        type=Path,
        metavar="RUN",
        help=with_default(
            "T-SCvx networks of --warmstart/--compare tscvx or best: a training run folder "
            "(scpformer train tscvx), or 'default': the networks shipped with scpformer for "
            "re-plans (tscvx-midflight, trained on states along optimal descents)",
            "default",
        ),
    )
    _add_run_arguments(parser)


def _add_loop_arguments(
    parser: argparse.ArgumentParser,
    warmstarts: tuple[str, ...],
    warmstart_help: str,
    *,
    replan_every: tuple[int, str],
    seed: str,
) -> None:
    """The warm start, comparison, re-planning period, run count and seed of a family's loop
    (``replan_every``: the default and what K counts)."""
    parser.add_argument("--warmstart", choices=warmstarts, default="cold",
                        help=with_default(warmstart_help, "cold"))  # fmt: skip
    parser.add_argument(
        "--compare",
        choices=warmstarts,
        default=None,
        help="also solve each re-plan with this warm start, for comparison only (not flown)",
    )
    default, unit = replan_every
    parser.add_argument("--replan-every", type=positive, default=default, metavar="K",
                        help=with_default(unit, default))  # fmt: skip
    parser.add_argument(
        "--time-budget",
        type=positive_seconds,
        default=None,
        metavar="SECONDS",
        help="wall seconds a re-plan may take; a later plan is not flown (the last accepted "
        "one flies on) and is recorded as late (default: no budget)",
    )
    parser.add_argument("--runs", type=positive, default=20, metavar="N",
                        help=with_default("number of runs", 20))  # fmt: skip
    parser.add_argument("--seed", type=count, default=0, metavar="S",
                        help=with_default(seed, 0))  # fmt: skip


def _add_instances_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """``--instances default|sampled``: what each run flies (``help_text``: in this family)."""
    parser.add_argument("--instances", choices=INSTANCES, default="default",
                        help=with_default(help_text, "default"))  # fmt: skip


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Where the runs go, how many processes fly them, and the handler (every family)."""
    parser.add_argument(
        "--workers",
        type=positive,
        default=1,
        metavar="W",
        help=with_default(
            "local processes flying runs side by side (the numbers do not change; re-plan "
            "wall times share the cores, so time with 1)",
            1,
        ),
    )
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        help="fly the runs as tasks on a Ray cluster ('local' starts one of W CPUs) instead of "
        "local processes; the files are written here",
    )
    parser.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    parser.add_argument("--no-figure", action="store_true", help="do not draw DIR/simulate.png")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=lazy_handler("scpformer.cli.simulate:run_simulate"))
