"""The T-SCvx rotation augmentation (Sec. III.E.2) as a dataset transform, checked.

Gravity, the landing target and every constraint of Eqs. 5-6 are symmetric about the Up axis
e1, so rotating a solved instance by an angle a about e1 gives a solved instance: with
``q_R = (cos a/2, sin a/2, 0, 0)``,

    r -> C(q_R) r,   v -> C(q_R) v,   q -> q_R (x) q,   omega, T_B, m, t_f unchanged,

and the tight constraints are the same rows. The paper rotates by 0, 45, ..., 315 deg, turning
1,592 solved instances into 11,634 samples. :func:`augment_dataset` writes the rotated copies
as a new dataset (one shard per source shard, resumable like generation) and checks each
rotated solution: propagated through the nonlinear model (``verify_trajectory``) and with
tight-constraint flags recomputed on the rotated instance. A copy failing either check keeps
its sample with status ``augmentation_check_failed``, so a failure is counted, not hidden.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from multiprocessing import get_context
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from scpformer import __version__
from scpformer.data import storage
from scpformer.data.errors import DatasetError
from scpformer.data.generate import repair
from scpformer.data.pdg6dof_family import PDG6DoFFamily, build, instance_from_theta
from scpformer.data.storage import Manifest
from scpformer.problems.pdg6dof.constraints import constraint_values, tight_flags
from scpformer.problems.pdg6dof.problem import verify_trajectory
from scpformer.problems.pdg6dof.symmetry import yaw_quaternion, yaw_states, yaw_theta
from scpformer.scp.solution import Trajectory
from scpformer.validation import check_int

ROTATION_ANGLES_DEG: tuple[float, ...] = tuple(45.0 * k for k in range(8))
CHECK_FAILED = "augmentation_check_failed"


@dataclass(frozen=True, kw_only=True)
class RotationAugmentation:
    """Rotations about Up applied to every (converged) sample; T-SCvx Sec. III.E.2."""

    angles_deg: tuple[float, ...] = ROTATION_ANGLES_DEG  # rotation angles about e1 [deg]
    converged_only: bool = True  # rotate only converged samples, drop the others
    verify: bool = True  # propagate every rotated solution through the nonlinear model
    name: ClassVar[str] = "rotation_about_up"

    def __post_init__(self) -> None:
        angles = tuple(float(a) for a in self.angles_deg)
        if not angles or not all(math.isfinite(a) for a in angles):
            raise ValueError(f"angles_deg must be finite and non-empty, got {self.angles_deg}")
        if len(set(angles)) != len(angles):
            raise ValueError(f"angles_deg must be distinct, got {self.angles_deg}")
        object.__setattr__(self, "angles_deg", angles)

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "config": dataclasses.asdict(self)}


def rotate_states(x: np.ndarray, angle_deg: float) -> np.ndarray:
    """States (..., 14) seen in the inertial frame rotated by ``angle_deg`` about Up."""
    return yaw_states(x, yaw_quaternion(angle_deg))


def rotate_theta(theta: np.ndarray, angle_deg: float) -> np.ndarray:
    """theta (..., 16) of the rotated instance (as :meth:`PDGInstance.rotated_about_up`)."""
    return yaw_theta(theta, yaw_quaternion(angle_deg))


def rotate_sample(sample: Mapping[str, Any], angle_deg: float, n_angles: int, k: int) -> dict:
    """One sample's fields rotated by ``angle_deg``; ``k`` numbers the angle (new index)."""
    out = dict(sample)
    out["theta"] = rotate_theta(sample["theta"], angle_deg)
    out["x"] = rotate_states(sample["x"], angle_deg)
    out["guess_x"] = rotate_states(sample["guess_x"], angle_deg)
    out["rotation_deg"] = float(sample["rotation_deg"]) + angle_deg
    out["index"] = int(sample["base_index"]) * n_angles + k
    return out


def check_rotated(
    family: PDG6DoFFamily, base: Mapping[str, Any], rotated: dict[str, Any], verify: bool
) -> dict[str, Any]:
    """Check a rotated solution (see the module docstring) and record the outcome in it."""
    constants, solver = family.config.constants, family.config.solver
    instance = instance_from_theta(base["theta"], constants)
    rotated_instance = instance_from_theta(rotated["theta"], constants)
    tol = solver.tight_tol
    flags = tight_flags(constraint_values(instance, base["x"], base["u"]), tol)
    new_flags = tight_flags(constraint_values(rotated_instance, rotated["x"], rotated["u"]), tol)
    problems = []
    if not np.array_equal(flags, new_flags):
        problems.append(f"{int(np.sum(flags != new_flags))} tight flag(s) changed")
    if verify and rotated["rotation_deg"] % 360.0 != 0.0:
        z = Trajectory(x=rotated["x"], u=rotated["u"], p=np.array([rotated["tf"]]))
        verification = verify_trajectory(rotated_instance, z, solver)
        rotated["verified"], rotated["max_defect"] = verification.passed, verification.max_defect
        if not verification.passed:
            problems.append(f"nonlinear check failed: {verification.message}")
    if problems:
        rotated["status"] = CHECK_FAILED
        rotated["message"] = f"rotation by {rotated['rotation_deg']:g} deg: " + "; ".join(problems)
    return rotated


def augment_columns(
    columns: Mapping[str, np.ndarray], family: PDG6DoFFamily, transform: RotationAugmentation
) -> list[dict[str, Any]]:
    """Rotated copies of one shard's samples, base-major then angle order."""
    keep = np.ones(len(columns["index"]), dtype=bool)
    if transform.converged_only:
        keep = np.isin(columns["status"].astype(str), list(family.success_statuses))
    n_angles = len(transform.angles_deg)
    out = []
    for row in np.flatnonzero(keep):
        base = {name: values[row] for name, values in columns.items()}
        converged = base["status"] in family.success_statuses
        for k, angle in enumerate(transform.angles_deg):
            rotated = rotate_sample(base, angle, n_angles, k)
            if converged:
                rotated = check_rotated(family, base, rotated, transform.verify)
            out.append(rotated)
    return out


# -- the dataset transform ---------------------------------------------------------------------
def augment_dataset(
    source: Path | str,
    out: Path | str,
    transform: RotationAugmentation | None = None,
    *,
    workers: int = 1,
    first: int | None = None,
    on_shard: Callable[[int, int], None] | None = None,
    on_notice: Callable[[str], None] | None = None,
) -> Manifest:
    """Write the rotated copies of the dataset at ``source`` as a new dataset at ``out``.

    Parameters
    ----------
    source
        A complete ``pdg6dof`` dataset made by ``generate`` (or, with ``first``, one whose
        first ``first`` instances are stored).
    out
        Folder of the augmented dataset (created; resumed when it holds this same transform).
    transform
        The augmentation (default: the paper's 8 rotations, checked).
    workers
        Processes that augment shards in parallel (the nonlinear check costs ~0.06 s a copy).
    first
        Rotate only base instances ``0 .. first - 1`` (a shard boundary): a smaller dataset
        of the same draws, or the finished part of a generation still running. ``generate
        --n first`` with the same seed draws the same instances (instance i uses child i of
        the seed).
    on_shard
        Called with (shards done, shards planned) after each shard.
    on_notice
        Called with one line per repair or resumption event.

    Returns
    -------
    Manifest
        The augmented dataset's manifest.
    """
    transform = transform or RotationAugmentation()
    source, out = Path(source), Path(out)
    src = _source_manifest(source, first)
    workers = check_int("workers", workers, least=1)
    if out.exists() and not out.is_dir():
        raise DatasetError(f"--out {out} is a file, not a folder")
    for info in src.shards:  # every source shard passes its checksum before any is read
        storage.require_intact(source, info)
    with storage.locked_folder(out):
        return _augment_locked(source, out, src, transform, workers, on_shard, on_notice)


def _augment_locked(
    source: Path,
    out: Path,
    src: Manifest,
    transform: RotationAugmentation,
    workers: int,
    on_shard: Callable[[int, int], None] | None,
    on_notice: Callable[[str], None] | None,
) -> Manifest:
    manifest = _prepare(source, out, src, transform, on_notice or (lambda _: None))
    family = build(src.config)
    todo = [i for i, _ in enumerate(src.shards) if storage.shard_name(i) not in _files(manifest)]
    jobs = [(source / src.shards[i].file, src.schema, family, transform) for i in todo]
    with _pool(workers) as pool:
        results = pool.map(_augment_shard, jobs) if pool else map(_augment_shard, jobs)
        for number, records in zip(todo, results, strict=True):
            manifest = _write(out, manifest, number, src.shards[number], records)
            if on_shard is not None:
                on_shard(len(manifest.shards), len(src.shards))
    return manifest


def _files(manifest: Manifest) -> set[str]:
    return {s.file for s in manifest.shards}


def _source_manifest(source: Path, first: int | None = None) -> Manifest:
    """The source's manifest (with ``first``: restricted to its first ``first`` instances)."""
    src = storage.read_manifest(source)
    if src.family != PDG6DoFFamily.name:
        raise DatasetError(f"the rotation augmentation is for pdg6dof datasets, not {src.family}")
    if src.kind != "generated":
        raise DatasetError(f"{source} is already a transformed dataset ({src.transform['name']})")
    if first is not None:
        return _first_instances(source, src, first)
    if not src.complete:
        raise DatasetError(
            f"{source} is incomplete: finish it with its generate command first, or rotate "
            "its finished part with --first N"
        )
    return src


def _first_instances(source: Path, src: Manifest, first: int) -> Manifest:
    """``src`` restricted to base instances ``0 .. first - 1``, which must all be stored."""
    first = check_int("first", first, least=1, most=src.n)
    prefix: list[storage.ShardInfo] = []  # the stored shards that run without gap from 0
    for shard in sorted(src.shards, key=lambda s: s.start):
        if shard.start != (prefix[-1].stop if prefix else 0) or shard.start >= first:
            break
        prefix.append(shard)
    if not (prefix and prefix[-1].stop == first):
        done = prefix[-1].stop if prefix else 0
        raise DatasetError(
            f"{source}: its first {first} instances are not all stored (shards of "
            f"{src.shard_size}; the stored ones run without gap up to {done}): choose a "
            "shard boundary that far, or finish the generation"
        )
    plan = tuple((s.start, s.stop) for s in prefix)  # a grown source's shards may be uneven
    return dataclasses.replace(src, n=first, shards=tuple(prefix), plan=plan)


def _prepare(
    source: Path,
    out: Path,
    src: Manifest,
    transform: RotationAugmentation,
    notice: Callable[[str], None],
) -> Manifest:
    wanted = dataclasses.replace(
        src,
        kind="transformed",
        transform=transform.to_dict(),
        source={
            "path": str(source.resolve()),
            "content_id": storage.content_id(src),
            "family": src.family,
            "seed": src.seed,
            "n": src.n,  # with --first: the first n instances of the source
        },
        plan=tuple((s.start, s.stop) for s in src.shards),
        grown_from=(),  # the source's history, not this dataset's
        shards=(),
        runs=(),
        package_version=__version__,
    )
    if out.exists() and not out.is_dir():
        raise DatasetError(f"--out {out} is a file, not a folder")
    out.mkdir(parents=True, exist_ok=True)
    if (out / storage.MANIFEST_NAME).exists():
        old = storage.read_manifest(out)
        why = storage.describe_mismatch(old, wanted)
        if why is not None:
            raise DatasetError(f"{out} holds another dataset: it differs in {why}")
        wanted = old
    elif any(
        not p.name.endswith(storage.TMP_SUFFIX) and p.name != storage.LOCK_NAME
        for p in out.iterdir()
    ):
        raise DatasetError(f"{out} is not empty and holds no dataset; choose an empty folder")
    manifest = repair(out, wanted, notice)
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")
    manifest = dataclasses.replace(manifest, runs=(*manifest.runs, {"started": started}))
    storage.write_manifest(out, manifest)
    return manifest


def _augment_shard(job: tuple[Path, tuple, PDG6DoFFamily, RotationAugmentation]) -> list[dict]:
    path, schema, family, transform = job
    return augment_columns(storage.read_columns(path, schema), family, transform)


class _NoPool:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def _pool(workers: int) -> Any:
    if workers <= 1:
        return _NoPool()
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("forkserver"))


def _write(
    out: Path, manifest: Manifest, number: int, src_shard: storage.ShardInfo, records: list
) -> Manifest:
    columns = storage.stack_records(records, manifest.schema)
    attrs = {**storage.shard_header(manifest), "transform": RotationAugmentation.name}
    return storage.append_shard(
        out,
        manifest,
        storage.shard_name(number),
        columns,
        start=src_shard.start,
        stop=src_shard.stop,
        attrs=attrs,
    )
