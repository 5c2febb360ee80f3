"""Lookup-table baselines of T-SCvx: k-d tree nearest neighbour and linear interpolation.

T-SCvx paper, Sec. IV.C (Tables 4-5): the tables predict the same quantities as the networks
from the same training data -- the tight-constraint flags of SCvx iteration k from
``(theta, k)``, and the solution ``(x, u, t_f)`` from ``theta`` -- on inputs standardized with
training statistics and compressed by PCA (``sklearn.decomposition``, 10 components in the
paper). Each table is one of

* ``kdtree``: the value of the nearest training point (``sklearn.neighbors.KDTree``);
* ``interp``: piecewise-linear interpolation over the Delaunay triangulation of the training
  points (``scipy.interpolate.LinearNDInterpolator``), the nearest point's value outside
  their convex hull.

The paper interpolates over a subset of 100 training points (the triangulation of n points
in 10 dimensions has on the order of 10^6 simplices: 1.6 GB and ~0.9 s per query in its
Table 4), so ``max_points`` defaults to 100 for ``interp``. For the k-d tree the paper's text
is ambiguous; ours keeps every training point (``max_points=0``), the baseline a k-d tree is
meant for; ``--max-points`` changes either.

Both expose the predictor API of the T-SCvx contract (``n_nodes``, ``predict_tight``,
``predict_tight_proba``, ``predict_solution``, raw theta in), so a
:class:`LookupPredictor` can stand wherever a ``TscvxPredictor`` does, e.g.
``TscvxWarmStart(load_lookup_predictor(RUN))``.

A run folder holds ``lookup.npz`` (standardization, PCA and table arrays) and
``lookup.json`` (kind, configuration, PCA dims, dataset content id, the npz's sha256). The
interpolation's triangulation is rebuilt from the stored points when loaded (qhull is
deterministic), as scipy cannot store one.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.interpolate import LinearNDInterpolator
from scipy.spatial import QhullError
from sklearn.decomposition import PCA
from sklearn.neighbors import KDTree

from scpformer.data.storage import file_sha256
from scpformer.data.tscvx_arrays import (
    N_THETA,
    SplitArrays,
    read_split_arrays,
    solution_stats,
    unflatten_solution,
)
from scpformer.files import atomic_path, write_text_atomic

LOOKUP_KINDS = ("kdtree", "interp")
LOOKUP_NPZ = "lookup.npz"
LOOKUP_JSON = "lookup.json"
LOOKUP_FORMAT = 1
META_KEYS = ("format", "kind", "config", "n_nodes", "pca_dims", "dataset_content_id", "npz_sha256")
PARTS = ("tight", "solution")  # (theta, k) -> flags; theta -> flat (x, u, t_f)
VARIANCE_FLOOR = 1e-10  # PCA components with less relative variance are dropped (flat data)


class LookupRunError(ValueError):
    """A lookup run folder that is missing, corrupt or inconsistent (one-line message)."""


@dataclass(frozen=True, kw_only=True)
class LookupConfig:
    """How a lookup table is built (paper Sec. IV.C)."""

    n_components: int = 10  # PCA components of the standardized inputs (paper: 10)
    max_points: int = 100  # training points in the table, drawn at random; 0: all (paper: 100)
    seed: int = 0  # seed of the draw of max_points
    threshold: float = 0.5  # predicted probability at and above which a row is tight
    leaf_size: int = 40  # k-d tree leaf size (scikit-learn's default)

    def __post_init__(self) -> None:
        if self.n_components < 1:
            raise ValueError(f"n_components must be >= 1, got {self.n_components}")
        if self.max_points < 0:
            raise ValueError(f"max_points must be >= 0 (0: all), got {self.max_points}")
        if not 0.0 < self.threshold < 1.0:
            raise ValueError(f"threshold must be in (0, 1), got {self.threshold}")
        if self.leaf_size < 1:
            raise ValueError(f"leaf_size must be >= 1, got {self.leaf_size}")


LOOKUP_PRESETS = {
    "kdtree": LookupConfig(max_points=0),  # every training point
    "interp": LookupConfig(max_points=100),  # the paper's 100-point table
}


# -- inputs: standardize, then PCA -----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class InputMap:
    """Raw inputs -> PCA components of the standardized inputs: ``((a - m) / s - c) W^T``."""

    mean: np.ndarray  # (d,) training mean of the raw inputs
    std: np.ndarray  # (d,) training std (floored to 1 for constant inputs)
    center: np.ndarray  # (d,) PCA mean of the standardized inputs
    components: np.ndarray  # (c, d) principal axes, c <= d

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        return ((raw - self.mean) / self.std - self.center) @ self.components.T  # (B, c)

    @property
    def dims(self) -> int:
        """c, the number of PCA components kept."""
        return int(self.components.shape[0])


def fit_input_map(
    raw: np.ndarray, mean: np.ndarray, std: np.ndarray, n_components: int
) -> InputMap:
    """PCA of the inputs ``raw`` (n, d) standardized with ``mean`` and ``std``.

    At most ``n_components`` axes are kept, fewer when the data span fewer dimensions (axes
    whose variance is below ``VARIANCE_FLOOR`` times the largest are dropped), so that a
    triangulation of the projected points is never flat.
    """
    z = (raw - mean) / std
    pca = PCA(n_components=min(n_components, z.shape[1], len(z)), svd_solver="full").fit(z)
    variance = pca.explained_variance_
    keep = variance > VARIANCE_FLOOR * max(float(variance.max(initial=0.0)), 1e-300)
    return InputMap(mean=mean, std=std, center=pca.mean_, components=pca.components_[keep])


# -- tables ----------------------------------------------------------------------------------------
class NearestTable:
    """The value of the nearest stored point (k-d tree, Euclidean in PCA space)."""

    def __init__(self, points: np.ndarray, values: np.ndarray, *, leaf_size: int = 40) -> None:
        self.points, self.values = points, values  # (n, c), (n, m)
        self.tree = KDTree(points, leaf_size=leaf_size)

    def __call__(self, z: np.ndarray) -> np.ndarray:
        index = self.tree.query(z, k=1, return_distance=False)[:, 0]
        return self.values[index].astype(float)  # (B, m)

    def nbytes(self) -> int:
        """Bytes of the tree's arrays and the stored values."""
        return sum(a.nbytes for a in self.tree.get_arrays()) + self.values.nbytes


class InterpolationTable:
    """Linear interpolation on the Delaunay triangulation; the nearest value outside the hull."""

    def __init__(self, points: np.ndarray, values: np.ndarray, *, leaf_size: int = 40) -> None:
        if points.shape[1] < 2:  # scipy triangulates in 2 or more dimensions only
            raise ValueError(
                f"interpolation needs inputs of at least 2 dimensions, the PCA kept "
                f"{points.shape[1]}; use n_components >= 2 and data that vary in 2 or more "
                "parameters, or the k-d tree"
            )
        if len(points) <= points.shape[1]:
            raise ValueError(
                f"interpolation in {points.shape[1]} dimensions needs more than "
                f"{points.shape[1]} points, got {len(points)}"
            )
        self.points, self.values = points, values
        try:
            self.interpolator = LinearNDInterpolator(
                points, values.astype(float), fill_value=np.nan
            )
        except QhullError as err:
            raise ValueError(
                f"cannot triangulate {len(points)} points in {points.shape[1]} dimensions "
                f"({_first_line(err)}); use fewer n_components or more points"
            ) from None
        self.nearest = NearestTable(points, values, leaf_size=leaf_size)

    def __call__(self, z: np.ndarray) -> np.ndarray:
        out = self.interpolator(z)  # (B, m), NaN outside the convex hull
        outside = np.isnan(out).any(axis=1)
        if outside.any():
            out[outside] = self.nearest(z[outside])
        return out

    def nbytes(self) -> int:
        """Bytes of the triangulation (points, simplices, neighbours, transforms) and values."""
        tri = self.interpolator.tri
        arrays = (tri.points, tri.simplices, tri.neighbors, tri.equations, tri.transform)
        return (
            sum(a.nbytes for a in arrays)
            + self.interpolator.values.nbytes
            + (self.nearest.nbytes())
        )


TABLES = {"kdtree": NearestTable, "interp": InterpolationTable}


# -- the predictor ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LookupPart:
    """One table with its input map: tight (theta, k) or solution theta."""

    inputs: InputMap
    table: NearestTable | InterpolationTable

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        return self.table(self.inputs(raw))


class LookupPredictor:
    """A lookup table behind the T-SCvx predictor API (as :mod:`scpformer.models.tscvx`).

    ``theta`` is raw (``theta_vector(instance)``), ``(16,)`` or ``(B, 16)``; ``k`` the 1-based
    SCvx iteration, an int or ``(B,)``. Outputs are unbatched for a ``(16,)`` theta with an
    int ``k``.
    """

    def __init__(
        self,
        *,
        kind: str,
        tight: LookupPart,
        solution: LookupPart,
        solution_mean: np.ndarray,
        solution_std: np.ndarray,
        n_nodes: int,
        config: LookupConfig,
        content_id: str = "",
    ) -> None:
        if kind not in LOOKUP_KINDS:
            raise ValueError(f"kind must be one of {LOOKUP_KINDS}, got {kind!r}")
        self.kind, self.config, self.content_id = kind, config, content_id
        self.tight, self.solution = tight, solution
        self.solution_mean, self.solution_std = solution_mean, solution_std  # (N * 17 + 1,)
        self._n_nodes = n_nodes
        self.threshold = config.threshold

    @property
    def n_nodes(self) -> int:
        """N, the number of temporal nodes of the predicted solution."""
        return self._n_nodes

    def predict_tight_proba(self, theta: np.ndarray, k: int | np.ndarray) -> np.ndarray:
        """Probability that each of the 7 N rows is tight at iteration k: (R,) or (B, R)."""
        thetas, single = theta_batch(theta)
        ks = k_batch(k, len(thetas), single)
        proba = np.clip(self.tight(np.column_stack([thetas, ks])), 0.0, 1.0)
        return proba[0] if single else proba

    def warm_up(self) -> None:
        """Nothing to prepare: the tables are built when the run is read."""

    def predict_tight(self, theta: np.ndarray, k: int | np.ndarray) -> np.ndarray:
        """Predicted tight flags (probability >= ``threshold``): bool (R,) or (B, R)."""
        return self.predict_tight_proba(theta, k) >= self.threshold

    def predict_solution(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any]:
        """Predicted ``(x (N, 14), u (N, 3), t_f)``, or batched ``(B, N, ...)``, ``(B,)``."""
        thetas, single = theta_batch(theta)
        flat = self.solution(thetas) * self.solution_std + self.solution_mean
        x, u, tf = unflatten_solution(flat, self.n_nodes)
        return (x[0], u[0], float(tf[0])) if single else (x, u, tf)

    def memory_bytes(self) -> int:
        """Bytes of the fitted arrays: standardization, PCA and both tables."""
        maps = [p.inputs for p in (self.tight, self.solution)]
        arrays = [a for m in maps for a in (m.mean, m.std, m.center, m.components)]
        extra = sum(a.nbytes for a in (*arrays, self.solution_mean, self.solution_std))
        return extra + self.tight.table.nbytes() + self.solution.table.nbytes()


def theta_batch(theta: Any) -> tuple[np.ndarray, bool]:
    """``theta`` as a finite float (B, 16) array, and whether it was a single (16,) vector."""
    try:
        array = np.asarray(theta, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"theta must be a numeric array, got {type(theta).__name__}") from None
    if array.ndim not in (1, 2) or array.shape[-1] != N_THETA or len(array) == 0:
        raise ValueError(f"theta must have shape ({N_THETA},) or (B, {N_THETA}), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError("theta must be finite (it holds NaN or inf)")
    return np.atleast_2d(array), array.ndim == 1


def k_batch(k: Any, batch: int, single: bool) -> np.ndarray:
    """``k`` as a (B,) float array of 1-based iterations (an int is repeated)."""
    array = np.asarray(k)
    if array.dtype.kind not in "iu":
        raise TypeError(f"k must be an integer or an integer array, got dtype {array.dtype}")
    if single and array.ndim != 0:
        raise ValueError(f"k must be an int for a single theta (16,), got shape {array.shape}")
    if array.ndim not in (0, 1) or (array.ndim == 1 and len(array) != batch):
        raise ValueError(f"k must be an int or have shape ({batch},), got shape {array.shape}")
    if (array < 1).any():
        raise ValueError("k must be >= 1 (1-based SCvx iteration)")
    return np.broadcast_to(array, (batch,)).astype(float)


# -- fitting ---------------------------------------------------------------------------------------
def fit_lookup(
    kind: str, data: SplitArrays | Path | str, config: LookupConfig | None = None
) -> LookupPredictor:
    """Fit both tables of ``kind`` on the training split (``data``: arrays or a folder)."""
    if kind not in LOOKUP_KINDS:
        raise ValueError(f"kind must be one of {LOOKUP_KINDS}, got {kind!r}")
    config = config or LOOKUP_PRESETS[kind]
    if not isinstance(data, SplitArrays):
        data = read_split_arrays(data, "train")
    if len(data.theta) == 0:
        raise ValueError("the training split holds no solved sample to fit a table on")
    theta_stats = data.splits.stats["theta"]
    mean, std = solution_stats(data.splits)
    rng = np.random.default_rng(config.seed)
    ks = data.item_k.astype(float)
    k_std = float(ks.std()) or 1.0
    tight = _fit_part(
        kind,
        np.column_stack([data.item_theta, ks]),
        data.flags,
        np.append(theta_stats.mean, ks.mean()),
        np.append(theta_stats.std, k_std),
        config,
        rng,
    )
    solution = _fit_part(
        kind, data.theta, (data.solution - mean) / std, theta_stats.mean, theta_stats.std,
        config, rng,
    )  # fmt: skip
    return LookupPredictor(
        kind=kind,
        tight=tight,
        solution=solution,
        solution_mean=mean,
        solution_std=std,
        n_nodes=data.n_nodes,
        config=config,
        content_id=data.content_id,
    )


def _fit_part(
    kind: str,
    raw: np.ndarray,
    values: np.ndarray,
    mean: np.ndarray,
    std: np.ndarray,
    config: LookupConfig,
    rng: np.random.Generator,
) -> LookupPart:
    """PCA on every training input, then a table over ``max_points`` of them (or all)."""
    keep = min(len(raw), config.max_points or len(raw))
    dims = config.n_components
    if kind == "interp":  # a triangulation needs more points than dimensions
        dims = min(dims, max(keep - 1, 1))
    inputs = fit_input_map(raw, mean, std, dims)
    if keep < len(raw):
        chosen = np.sort(rng.choice(len(raw), size=keep, replace=False))
        raw, values = raw[chosen], values[chosen]
    table = TABLES[kind](inputs(raw), values, leaf_size=config.leaf_size)
    return LookupPart(inputs=inputs, table=table)


# -- run folder ------------------------------------------------------------------------------------
def save_lookup(predictor: LookupPredictor, run_dir: Path | str) -> Path:
    """Write ``RUN/lookup.npz`` and ``RUN/lookup.json``; returns the run folder."""
    run = Path(run_dir)
    run.mkdir(parents=True, exist_ok=True)
    arrays = {"target_mean": predictor.solution_mean, "target_std": predictor.solution_std}
    for name in PARTS:
        part: LookupPart = getattr(predictor, name)
        for key in ("mean", "std", "center", "components"):
            arrays[f"{name}_{key}"] = getattr(part.inputs, key)
        arrays[f"{name}_points"] = part.table.points
        arrays[f"{name}_values"] = part.table.values
    npz = run / LOOKUP_NPZ
    with atomic_path(npz) as tmp, tmp.open("wb") as fh:  # a full disk keeps an earlier table
        np.savez_compressed(fh, **arrays)
    meta = {
        "format": LOOKUP_FORMAT,
        "kind": predictor.kind,
        "config": dataclasses.asdict(predictor.config),
        "n_nodes": predictor.n_nodes,
        "pca_dims": {name: getattr(predictor, name).inputs.dims for name in PARTS},
        "points": {name: len(getattr(predictor, name).table.points) for name in PARTS},
        "dataset_content_id": predictor.content_id,
        "npz_sha256": file_sha256(npz),
    }
    write_text_atomic(run / LOOKUP_JSON, json.dumps(meta, indent=2) + "\n")
    return run


def load_lookup_predictor(run_dir: Path | str) -> LookupPredictor:
    """The lookup table of ``scpformer train kdtree|interp --out RUN``.

    Raises
    ------
    LookupRunError
        When ``RUN`` holds no lookup table, or its files are corrupt or do not match.
    """
    run = Path(run_dir)
    meta = _read_meta(run)
    npz = run / LOOKUP_NPZ
    if not npz.is_file():
        raise LookupRunError(f"{npz} is missing; rerun `scpformer train {meta['kind']}`")
    if file_sha256(npz) != meta["npz_sha256"]:
        raise LookupRunError(f"{npz} does not match {run / LOOKUP_JSON} (changed or corrupt)")
    try:
        with np.load(npz, allow_pickle=False) as stored:
            arrays = {key: stored[key] for key in stored.files}
        config = LookupConfig(**meta["config"])
        parts = {name: _load_part(meta["kind"], name, arrays, config) for name in PARTS}
        return LookupPredictor(
            kind=meta["kind"],
            solution_mean=arrays["target_mean"],
            solution_std=arrays["target_std"],
            n_nodes=int(meta["n_nodes"]),
            config=config,
            content_id=str(meta["dataset_content_id"]),
            **parts,
        )
    except (KeyError, TypeError, ValueError, OSError) as err:
        raise LookupRunError(f"{npz} is corrupt ({_first_line(err)})") from None


def _read_meta(run: Path) -> dict[str, Any]:
    path = run / LOOKUP_JSON
    if not path.is_file():
        raise LookupRunError(f"no lookup table in {run}: run `scpformer train kdtree|interp`")
    try:
        meta = json.loads(path.read_text())
        if not isinstance(meta, dict):
            raise TypeError("not a JSON object")
        missing = [key for key in META_KEYS if key not in meta]
        if missing:
            raise ValueError(f"missing {missing}")
        if meta["format"] != LOOKUP_FORMAT or meta["kind"] not in LOOKUP_KINDS:
            raise ValueError(f"format {meta['format']!r}, kind {meta['kind']!r}")
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise LookupRunError(f"{path} is corrupt ({_first_line(err)})") from None
    return meta


def _load_part(kind: str, name: str, arrays: dict, config: LookupConfig) -> LookupPart:
    inputs = InputMap(*(arrays[f"{name}_{key}"] for key in ("mean", "std", "center", "components")))
    points, values = arrays[f"{name}_points"], arrays[f"{name}_values"]
    if points.shape[1] != inputs.dims or len(points) != len(values):
        raise ValueError(f"{name} table shapes {points.shape}, {values.shape} disagree")
    table = TABLES[kind](points, values, leaf_size=config.leaf_size)
    return LookupPart(inputs=inputs, table=table)


def _first_line(err: BaseException) -> str:
    return (str(err).splitlines() or [type(err).__name__])[0][:200]


def train_lookup(
    kind: str, *, data: Path | str, out: Path | str, config: LookupConfig | None = None
) -> LookupPredictor:
    """``scpformer train kdtree|interp``: fit on ``data``'s training split, save to ``out``.

    Raises ``ValueError`` before fitting when ``out`` already holds a lookup table: it is not
    replaced unasked.
    """
    for name, what in (("manifest.json", "a dataset"), ("checkpoint.pt", "a training run")):
        if (Path(out) / name).exists() or any(Path(out).glob(f"*/{name}")):
            raise ValueError(
                f"--out {out} holds {what} ({name}): the lookup table would be written among "
                "its files; give another --out"
            )
    taken = [name for name in (LOOKUP_JSON, LOOKUP_NPZ) if (Path(out) / name).exists()]
    if taken:
        raise ValueError(
            f"--out {out} already holds a lookup table ({', '.join(taken)}); give another "
            "--out, or delete it"
        )
    predictor = fit_lookup(kind, data, config)
    save_lookup(predictor, out)
    return predictor
