"""``scpformer generate FAMILY`` and ``scpformer dataset info|verify|augment|split``.

Register with :func:`add_generate_parser` and :func:`add_dataset_parser` on the top-level
subparsers; ``python -m scpformer.cli.data`` runs both on their own. A family gets the common
generation flags; its own flags (e.g. solver settings) come from :data:`FAMILY_ARGUMENTS`,
where a family that lands registers them with :func:`register_family_arguments`.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from scpformer.cli.argtypes import count, positive
from scpformer.cli.commands import add_command_parser
from scpformer.cli.config_file import ConfigParser, add_config_file_arguments
from scpformer.cli.dataclass_args import add_dataclass_arguments, constant, with_default
from scpformer.cli.errors import Terminated, run_command
from scpformer.cli.parsers import pdg6dof as pdg6dof_flags
from scpformer.cli.parsers import rendezvous as rendezvous_flags
from scpformer.cli.parsers import robust_rendezvous as robust_flags
from scpformer.cli.parsers.common import FlagSpec, add_flags

if TYPE_CHECKING:  # the parsers import none of the library (``--help`` stays fast)
    from scpformer.data.family import DatasetFamily
    from scpformer.data.generate import GenerationReport, Progress
    from scpformer.data.storage import Manifest


@dataclass(frozen=True)
class FamilyArguments:
    """A family's own ``generate`` flags and how to build the family from them."""

    add: Callable[[argparse.ArgumentParser], None]
    build: Callable[[argparse.Namespace], DatasetFamily]


FAMILY_ARGUMENTS: dict[str, FamilyArguments] = {}


def register_family_arguments(
    name: str,
    add: Callable[[argparse.ArgumentParser], None],
    build: Callable[[argparse.Namespace], DatasetFamily],
) -> None:
    """Give family ``name`` its own ``generate`` flags (e.g. ``--mode`` of robust-rendezvous)."""
    FAMILY_ARGUMENTS[name] = FamilyArguments(add=add, build=build)


def family_flags(
    flags: tuple[FlagSpec, ...],
    add_config: Callable[[argparse.ArgumentParser], None],
    ranges: str | None = None,
) -> Callable[[argparse.ArgumentParser], None]:
    """The ``add`` of :func:`register_family_arguments` of a family built from a table.

    Parameters
    ----------
    flags
        The family's own flags, in the order of ``--help``.
    add_config
        Adds the family's solver settings (``add_config_arguments`` of its parsers module).
    ranges
        The snapshot name of its sampling ranges, flags ``--range-NAME`` (None: none).

    Returns
    -------
    Callable
        Adds ``flags``, the ranges and the settings to a ``generate FAMILY`` parser.
    """

    def add(parser: argparse.ArgumentParser) -> None:
        add_flags(parser, flags)
        if ranges is not None:
            add_dataclass_arguments(
                parser, ranges, prefix="range", title="sampling ranges of theta (Table 1)"
            )
        add_config(parser)

    return add


PDG6DOF_FLAGS: tuple[FlagSpec, ...] = (
    ("--ranges", {
        "choices": "pdg6dof.ranges",
        "default": "feasible",
        "help": "sampling ranges of theta: Table 2's parameters drawn consistently with the "
        "constraints (feasible), Table 2 as an independent box (table2), or the nominal "
        "sub-range (default: feasible)",
    }),
    ("--midflight-nodes", {
        "type": positive, "nargs": 2, "metavar": ("A", "B"), "default": None,
        "help": "sample states along optimal descents instead: solve each drawn instance "
        "with cold SCvx and start the sample from its state at a node drawn from A..B "
        "(the states a re-planning guidance meets; default: the drawn initial states)",
    }),
)  # fmt: skip
RENDEZVOUS_FLAGS: tuple[FlagSpec, ...] = (
    ("--warmstart", {
        "choices": "rendezvous.warmstarts",
        "default": "convex",
        "help": "initial reference of Problem 3 (default: convex, the stored convex twin)",
    }),
    ("--no-verify", {
        "action": "store_true",
        "help": "skip the nonlinear replay of the twins (about 4x faster; statuses then rest "
        "on the linear model alone)",
    }),
    ("--no-tpbvp-twin", {
        "action": "store_true",
        "help": "store the Problem 2 and 3 twins only, not the Problem 1 (TPBVP) twin of "
        "Table 2",
    }),
)  # fmt: skip
ROBUST_RENDEZVOUS_FLAGS: tuple[FlagSpec, ...] = (
    ("--mode", {
        "choices": "robust.modes",
        "default": "chance",
        "help": "passive safety of the last stage: deterministic (X = 0) or chance (default)",
    }),
    ("--no-verify", {
        "action": "store_true",
        "help": "skip the final check of each stage (statuses then rest on SCvx* alone)",
    }),
)  # fmt: skip


def _build_pdg6dof(args: argparse.Namespace) -> DatasetFamily:
    from scpformer.cli.dataclass_args import overrides
    from scpformer.cli.pdg6dof import config_from_args
    from scpformer.data.pdg6dof_family import RANGE_PRESETS, PDG6DoFDataConfig, PDG6DoFFamily
    from scpformer.problems.pdg6dof.constants import VehicleConstants

    constants = VehicleConstants(**overrides(args, VehicleConstants, "const"))
    nodes = args.midflight_nodes
    config = PDG6DoFDataConfig(
        ranges=RANGE_PRESETS[args.ranges](), constants=constants, solver=config_from_args(args),
        midflight_nodes=None if nodes is None else tuple(nodes),
    )  # fmt: skip
    return PDG6DoFFamily(config)


def _build_rendezvous(args: argparse.Namespace) -> DatasetFamily:
    from scpformer.cli.dataclass_args import overrides
    from scpformer.cli.rendezvous import config_from_args, scenario_from_args
    from scpformer.data.rendezvous_family import RendezvousDataConfig, RendezvousFamily
    from scpformer.problems.rendezvous.instance import SampleRanges

    scenario, target = scenario_from_args(args)
    config = RendezvousDataConfig(
        ranges=SampleRanges(**overrides(args, SampleRanges, "range")),
        scenario=scenario,
        target=target,
        solver=config_from_args(args),
        warmstart=args.warmstart,
        verify=not args.no_verify,
        tpbvp_twin=not args.no_tpbvp_twin,
    )
    return RendezvousFamily(config)


def _build_robust_rendezvous(args: argparse.Namespace) -> DatasetFamily:
    from scpformer.cli.dataclass_args import overrides
    from scpformer.cli.robust_rendezvous import common_from_args, config_from_args
    from scpformer.data.robust_rendezvous_family import RobustDataConfig, RobustRendezvousFamily
    from scpformer.problems.robust_rendezvous.instance import RobustSampleRanges

    config = RobustDataConfig(
        ranges=RobustSampleRanges(**overrides(args, RobustSampleRanges, "range")),
        solver=config_from_args(args),
        mode=args.mode,
        verify=not args.no_verify,
        **common_from_args(args, None),
    )
    return RobustRendezvousFamily(config)


register_family_arguments(
    "pdg6dof", family_flags(PDG6DOF_FLAGS, pdg6dof_flags.add_config_arguments), _build_pdg6dof
)
register_family_arguments(
    "rendezvous",
    family_flags(RENDEZVOUS_FLAGS, rendezvous_flags.add_config_arguments, "rendezvous.ranges"),
    _build_rendezvous,
)
register_family_arguments(
    "robust-rendezvous",
    family_flags(ROBUST_RENDEZVOUS_FLAGS, robust_flags.add_config_arguments, "robust.ranges"),
    _build_robust_rendezvous,
)


# -- generate ----------------------------------------------------------------------------------
def add_generate_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``generate FAMILY`` with one sub-command per known family."""
    parser = add_command_parser(subparsers, "", "generate")
    families = parser.add_subparsers(dest="family", required=True, metavar="FAMILY")
    for name, summary in _family_summaries().items():
        sub = families.add_parser(name, help=summary, description=summary)
        _add_common_generate_arguments(sub)
        if name in FAMILY_ARGUMENTS:
            FAMILY_ARGUMENTS[name].add(sub)
        else:
            add_config_file_arguments(sub)
        sub.set_defaults(handler=run_generate, family_name=name)


def _family_summaries() -> dict[str, str]:
    """``name -> summary`` of every family: the built-in ones from the snapshot
    (:mod:`scpformer.cli.schema`, without importing them), and those registered at run time
    when the registry is loaded."""
    summaries = dict(constant("families"))
    registry = sys.modules.get("scpformer.data.family")
    if registry is not None:
        from scpformer.data.errors import DatasetError

        for name in registry.family_names():
            if name not in summaries:
                try:
                    summaries[name] = registry.get_family_spec(name).summary
                except DatasetError:
                    summaries[name] = "(not available yet)"
    return summaries


#: the flags of every ``generate FAMILY``, group ``generation``
GENERATION_FLAGS: tuple[FlagSpec, ...] = (
    ("--n", {"type": positive, "required": True,
             "help": "number of instances; a larger --n on an existing dataset grows it"}),
    ("--out", {"type": Path, "required": True, "help": "dataset folder"}),
    ("--seed", {"type": count, "default": 0,
                "help": with_default("root seed of the dataset", 0)}),
    ("--workers", {"type": positive,
                   "help": "worker processes or Ray actors (default: every CPU)"}),
    ("--ray", {"metavar": "ADDRESS",
               "help": "run on the Ray cluster at ADDRESS ('auto', 'ray://host:port'; 'local' "
               "starts one)"}),
    ("--shard-size", {"type": positive, "default": 64,
                      "help": with_default("instances per shard", 64)}),
    ("--time-limit", {"type": float, "default": 300.0, "metavar": "SECONDS",
                      "help": with_default("per-instance limit; past it the worker is restarted "
                                           "and the instance stored with status timeout", 300.0)}),
    ("--quiet", {"action": "store_true", "help": "no progress bar"}),
)  # fmt: skip


def _add_common_generate_arguments(parser: argparse.ArgumentParser) -> None:
    add_flags(parser.add_argument_group("generation"), GENERATION_FLAGS)


class _ProgressBar:
    """tqdm bar with solved and failed counts; rate and time left are tqdm's own."""

    def __init__(self, desc: str, disable: bool) -> None:
        self.desc, self.disable = desc, disable
        self.bar = None

    def __call__(self, progress: Progress) -> None:
        from scpformer.data.family import ERROR, TIMEOUT, WORKER_CRASHED

        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(
                total=progress.total,
                initial=progress.done,
                desc=self.desc,
                unit="inst",
                file=sys.stderr,
                dynamic_ncols=True,
                disable=self.disable,
            )
        self.bar.set_postfix(solved=progress.solved, failed=progress.failed, refresh=False)
        if progress.result is not None:
            self.bar.update(1)
        result = progress.result
        if result is not None and result.status in (TIMEOUT, WORKER_CRASHED, ERROR):
            self.write(f"instance {result.index}: {result.status}: {result.message}")

    def write(self, text: str) -> None:
        from tqdm import tqdm

        tqdm.write(f"scpformer: {text}", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def run_generate(args: argparse.Namespace) -> int:
    """Handler of ``generate FAMILY``."""
    from scpformer.data.executors import check_ray_address
    from scpformer.data.family import build_family, get_family_spec
    from scpformer.data.generate import GenerateConfig, generate
    from scpformer.files import check_output_folder

    name = args.family_name
    check_output_folder(args.out, "--out")
    if args.ray:
        check_ray_address(args.ray)
    if name in FAMILY_ARGUMENTS:
        get_family_spec(name)  # a clear error if the family has not landed
        family = FAMILY_ARGUMENTS[name].build(args)
    else:
        family = build_family(name)
    config = GenerateConfig(
        n=args.n,
        out=args.out,
        seed=args.seed,
        shard_size=args.shard_size,
        workers=args.workers,
        ray_address=args.ray,
        time_limit=args.time_limit,
    )
    bar = _ProgressBar(name, disable=args.quiet)
    try:
        report = generate(family, config, on_progress=bar, on_notice=bar.write)
    except (KeyboardInterrupt, Terminated) as stop:
        raise type(stop)("finished shards are kept: re-run the same command to resume") from None
    finally:
        bar.close()
    print("\n".join(report_lines(report)))
    return 0


def report_lines(report: GenerationReport) -> list[str]:
    """A few lines on what a generate run did."""
    counts = report.manifest.counts()
    lines = [
        f"wrote {report.folder}: {counts['samples']} of {report.manifest.n} instances in "
        f"{counts['shards']} shard(s)",
        _solved_line(report.manifest),
    ]
    if report.generated:
        rate = report.generated / report.wall_time
        lines.append(
            f"this run: {report.generated} instances in {report.wall_time:.1f} s "
            f"({rate:.2f}/s, {report.workers} {report.backend} worker(s), warm-up "
            f"{report.startup_time:.1f} s); solver busy {report.solver_share:.0%} of worker time"
        )
    return lines


def _solved_line(manifest: Manifest) -> str:
    counts = manifest.counts()
    total = max(counts["samples"], 1)
    statuses = ", ".join(f"{k} {v}" for k, v in counts["by_status"].items()) or "none"
    return (
        f"solved {counts['solved']} ({counts['solved'] / total:.1%}), failed "
        f"{counts['failed']} ({counts['failed'] / total:.1%}): {statuses}"
    )


# -- dataset -----------------------------------------------------------------------------------
def add_dataset_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``dataset info|verify|repair|augment|split`` (see :data:`DATASET_COMMANDS`)."""
    parser = add_command_parser(subparsers, "", "dataset")
    commands = parser.add_subparsers(dest="dataset_command", required=True, metavar="COMMAND")
    for name, summary, description, handler, add_arguments in DATASET_COMMANDS:
        sub = commands.add_parser(name, help=summary, description=description or summary)
        add_arguments(sub)
        sub.set_defaults(handler=handler)


def _add_folder_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", type=Path, metavar="DIR")


INFO_FLAGS: tuple[FlagSpec, ...] = (
    ("--table2", {
        "action": "store_true",
        "help": "pdg6dof: min and max of theta and K over the converged samples, beside "
        "Table 2 of the T-SCvx paper",
    }),
)  # fmt: skip


def _add_info_arguments(parser: argparse.ArgumentParser) -> None:
    _add_folder_argument(parser)
    add_flags(parser, INFO_FLAGS)


def _add_augment_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", type=Path, metavar="SRC")
    parser.add_argument("--out", type=Path, required=True, help="augmented dataset folder")
    parser.add_argument(
        "--angles",
        type=float,
        nargs="+",
        default=list(constant("rotation_angles")),
        help="rotation angles about Up in degrees (0 45 ... 315)",
    )
    parser.add_argument("--no-verify", action="store_true", help="skip the nonlinear check")
    parser.add_argument(
        "--all-statuses", action="store_true", help="rotate failed samples too (default: drop)"
    )
    parser.add_argument("--workers", type=positive, default=1, help="processes (1)")
    parser.add_argument(
        "--first",
        type=positive,
        default=None,
        metavar="N",
        help="rotate only the first N base instances (a shard boundary; SRC may still be "
        "generating): the same draws as generate --n N with SRC's seed",
    )


def _add_split_arguments(parser: argparse.ArgumentParser) -> None:
    _add_folder_argument(parser)
    parser.add_argument(
        "--fractions",
        type=float,
        nargs=3,
        default=[0.8, 0.0, 0.2],
        metavar=("TRAIN", "VALIDATION", "TEST"),
        help="shares of the groups (0.8 0 0.2)",
    )
    parser.add_argument("--seed", type=count, default=0, help="seed of the group permutation (0)")
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace existing splits made with other settings (runs trained on them then "
        "no longer match their data)",
    )


def run_info(args: argparse.Namespace) -> int:
    """Handler of ``dataset info DIR [--table2]``."""
    from scpformer.data.family import check_family_name
    from scpformer.data.storage import MANIFEST_NAME, read_manifest, require_consistent

    manifest = read_manifest(args.dir)
    check_family_name(manifest.family, f"{Path(args.dir) / MANIFEST_NAME}: ")
    require_consistent(args.dir, manifest)
    lines = info_lines(args.dir, manifest)
    if args.table2:
        from scpformer.data.pdg6dof_family import dataset_table2_lines

        lines += ["", *dataset_table2_lines(args.dir)]
    print("\n".join(lines))
    return 0


def info_lines(folder: Path, manifest: Manifest) -> list[str]:
    """A human-readable summary of a dataset."""
    from scpformer.data.errors import DatasetError
    from scpformer.data.splits import SPLITS_NAME, load_splits
    from scpformer.data.storage import shard_damage

    counts = manifest.counts()
    kind = manifest.kind
    if manifest.transform is not None:
        kind += f" by {manifest.transform['name']} from {manifest.source['path']}"
    damaged = [d for d in (shard_damage(folder, s) for s in manifest.shards) if d is not None]
    state = "complete" if manifest.complete else "incomplete: re-run generate to finish"
    if damaged:
        state = (
            f"incomplete: {len(damaged)} listed shard(s) missing or damaged ({damaged[0]}); "
            "re-run generate to redo them"
        )
    size = sum(s.bytes for s in manifest.shards) / 1e6
    rows = [
        ("dataset", str(folder)),
        ("family", f"{manifest.family} ({kind})"),
        ("seed", str(manifest.seed)),
        ("samples", f"{counts['samples']} from {manifest.n} planned instances ({state})"),
        ("shards", f"{counts['shards']} of {counts['planned_shards']}, {size:.1f} MB"),
        ("outcome", _solved_line(manifest)),
        ("written by", f"scpformer {manifest.package_version}, {manifest.versions}"),
    ]
    if manifest.grown_from:
        sizes = " -> ".join(str(n) for n in (*manifest.grown_from, manifest.n))
        rows.insert(4, ("grown", f"{sizes} instances"))
    if (folder / SPLITS_NAME).is_file():
        try:
            splits = load_splits(folder)
            sizes = ", ".join(f"{k} {len(v)}" for k, v in splits.indices.items())
            rows.append(("splits", f"{sizes} (grouped by {splits.config.group_field})"))
        except DatasetError as err:
            rows.append(("splits", str(err)))
    rows += [(f"field {f.name}", f"{f.dtype} {f.shape}  {f.doc}".rstrip()) for f in manifest.schema]
    width = max(len(k) for k, _ in rows)
    return [f"{k:<{width}}  {v}" for k, v in rows]


def run_verify(args: argparse.Namespace) -> int:
    """Handler of ``dataset verify DIR``: exit 0 when clean, 1 with one line per problem."""
    from scpformer.data.splits import check_splits
    from scpformer.data.storage import read_manifest, verify_dataset

    manifest = read_manifest(args.dir)
    problems = verify_dataset(args.dir) + check_splits(args.dir)
    for problem in problems:
        print(f"{args.dir}: {problem}")
    if problems:
        print(f"{len(problems)} problem(s) found")
        return 1
    counts = manifest.counts()
    print(
        f"ok: {args.dir}: {counts['shards']} shard(s), {counts['samples']} samples; "
        "checksums, fields and shapes verified"
    )
    return 0


def run_repair(args: argparse.Namespace) -> int:
    """Handler of ``dataset repair DIR``."""
    from scpformer.data.generate import rebuild_manifest

    manifest = rebuild_manifest(args.dir, lambda text: print(f"scpformer: {text}", file=sys.stderr))
    counts = manifest.counts()
    print(
        f"rebuilt {args.dir}/manifest.json: {counts['shards']} of {counts['planned_shards']} "
        f"shard(s), {counts['samples']} samples"
    )
    return 0


def run_augment(args: argparse.Namespace) -> int:
    """Handler of ``dataset augment SRC --out DST``."""
    from tqdm import tqdm

    from scpformer.data.augment import RotationAugmentation, augment_dataset
    from scpformer.files import check_output_folder

    check_output_folder(args.out, "--out")
    transform = RotationAugmentation(
        angles_deg=tuple(args.angles),
        converged_only=not args.all_statuses,
        verify=not args.no_verify,
    )
    bars: list[Any] = []  # made at the first shard: an early error stays one line

    def on_shard(done: int, total: int) -> None:
        if not bars:
            bars.append(tqdm(desc="augment", unit="shard", file=sys.stderr, total=total))
        bars[0].update(done - bars[0].n)

    try:
        manifest = augment_dataset(
            args.source,
            args.out,
            transform,
            workers=args.workers,
            first=args.first,
            on_shard=on_shard,
            on_notice=lambda text: tqdm.write(f"scpformer: {text}", file=sys.stderr),
        )
    finally:
        for bar in bars:
            bar.close()
    print(f"wrote {args.out}: {manifest.counts()['samples']} samples")
    print(_solved_line(manifest))
    return 0


def run_split(args: argparse.Namespace) -> int:
    """Handler of ``dataset split DIR``."""
    from scpformer.data.splits import SplitConfig, make_splits

    config = SplitConfig(fractions=tuple(args.fractions), seed=args.seed)
    splits = make_splits(args.dir, config, force=args.force)
    sizes = ", ".join(f"{k} {len(v)}" for k, v in splits.indices.items())
    print(f"wrote {args.dir}/splits.h5: {sizes} samples; statistics of {sorted(splits.stats)}")
    return 0


#: ``dataset`` sub-commands: name, summary, description (None: the summary), handler, and
#: what adds their arguments
DATASET_COMMANDS: tuple[
    tuple[
        str,
        str,
        str | None,
        Callable[[argparse.Namespace], int],
        Callable[[argparse.ArgumentParser], None],
    ],
    ...,
] = (
    ("info", "summarize a dataset", None, run_info, _add_info_arguments),
    ("verify", "check checksums, fields and shapes", None, run_verify, _add_folder_argument),
    ("repair", "rebuild a deleted manifest.json from the headers the shards carry", None,
     run_repair, _add_folder_argument),
    ("augment", "rotate a pdg6dof dataset about Up (T-SCvx augmentation)",
     "Write the rotated copies of every converged sample as a new dataset; each rotated "
     "solution is checked with the nonlinear model and its tight flags.",
     run_augment, _add_augment_arguments),
    ("split", "grouped train/validation/test splits and training statistics",
     "Split by base instance (augmented copies stay together) and store the training "
     "split's normalization statistics in DIR/splits.h5.",
     run_split, _add_split_arguments),
)  # fmt: skip


# -- standalone entry point --------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    """A parser with only ``generate`` and ``dataset`` (what ``scpformer`` adds them to)."""
    parser = ConfigParser(prog="scpformer", description="scpformer datasets")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_generate_parser(commands)
    add_dataset_parser(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run ``generate`` or ``dataset``; every failure ends with one ``error:`` line."""
    return run_command(build_parser(), argv)


if __name__ == "__main__":
    sys.exit(main())
