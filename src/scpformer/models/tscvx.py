"""The T-SCvx networks (T-SCvx paper Sec. III.C-D, Table 3) and the predictor the solver calls.

Notation
--------
theta (16,)   instance parameters in :data:`scpformer.data.pdg6dof_family.THETA_NAMES` order
k             SCvx iteration, 1-based (Algorithm 2, step 1: tau = f2(theta, k + 1))
N             temporal nodes; R = 7 N inequality rows, name-major
              (:func:`scpformer.problems.pdg6dof.constraints.constraint_index`)
f2            :class:`TightClassifier`, (theta, k) -> one logit per row (B, R)
f1            :class:`SolutionRegressor`, theta -> standardized (x, u, t_f), (B, 17 N + 1):
              ``x.reshape(14 N)``, then ``u.reshape(3 N)``, then ``t_f``

Both are the transformer encoder of Sec. III.D.1: a linear encoder to the embedding width, a
learned position encoding, ``torch.nn.TransformerEncoder`` layers (multi-head attention of
Eq. 23, feed-forward, dropout, LayerNorm) and a linear decoder. How the inputs become tokens
is a configuration field (``tokens``):

* ``single`` -- the whole input vector is one token (the paper's layout: its input size 17,
  output size 12 N; with PyTorch's default feed-forward width 2048, the paper's classifier
  sizes give Table 3's 8.91 M parameters). Attention over one token is a linear map, so the
  network is a residual MLP; the cheapest to train and to run.
* ``inputs`` -- one token per input scalar (``value * w_i + b_i``, the learned position
  encoding being ``b_i``) plus one learned read-out token whose output is decoded; attention
  then mixes the parameters. Measured: ~9x the training compute of ``single`` for f2.

``TSCVX_PRESETS['paper']`` uses ``single``, ``TSCVX_PRESETS['small']`` uses ``inputs``.

The iteration k enters the classifier as a 17th input, ``2 (k - 1) / (iter_max - 1) - 1``
(-1 at the first iteration, +1 at ``iter_max``, the dataset's iteration limit).

Usage::

    predictor = load_tscvx_predictor(run_dir)  # RUN/tight/best.pt, RUN/solution/best.pt
    flags = predictor.predict_tight(theta, k)  # (R,) bool, theta raw (16,)
    x, u, tf = predictor.predict_solution(theta)  # (N, 14), (N, 3), float

``TSCVX_PRESETS['small']`` was chosen by measuring on this machine; see its comment.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from scpformer.data.splits import Splits
from scpformer.models.checkpoint import load_checkpoint
from scpformer.models.normalization import _floored, _per_step_floor
from scpformer.problems.pdg6dof import symmetry as sym
from scpformer.validation import check_int, shown, shown_as

N_THETA = 16  # parameters of theta (THETA_NAMES)
N_CONSTRAINT_NAMES = 7  # rows per node (CONSTRAINT_NAMES)
STATE_DIM, CONTROL_DIM = 14, 3  # x and u per node
TOKENIZATIONS = ("single", "inputs")
TIGHT_KIND, SOLUTION_KIND = "tscvx-tight", "tscvx-solution"
MODEL_KINDS = (TIGHT_KIND, SOLUTION_KIND)
FAMILY = "pdg6dof"


# ======================================================================================
# configuration
# ======================================================================================
@dataclass(frozen=True, kw_only=True)
class EncoderSizes:
    """Sizes shared by both networks (Sec. III.D.1; Sec. IV.A for the paper's values)."""

    d_model: int = 384  # embedding width of the encoder layers
    n_head: int = 2  # attention heads (Eq. 23)
    n_layer: int = 4  # transformer encoder layers
    d_ff: int = 2048  # feed-forward width (PyTorch's default; not given in the paper)
    dropout: float = 0.1  # dropout in the encoder layers (training only)
    tokens: str = "single"  # "single" (whole input one token) or "inputs" (one per scalar)
    n_nodes: int = 50  # N, temporal nodes (Table 1)

    def __post_init__(self) -> None:
        for name in ("d_model", "n_head", "n_layer", "d_ff", "n_nodes"):
            object.__setattr__(self, name, check_int(name, getattr(self, name), least=1))
        if self.d_model % self.n_head:
            raise ValueError(
                f"d_model ({self.d_model}) must be divisible by n_head ({self.n_head})"
            )
        if not isinstance(self.dropout, int | float) or not 0.0 <= self.dropout < 1.0:
            raise ValueError(
                f"dropout must be in [0, 1), got {shown_as(self.dropout, int | float)}"
            )
        if self.tokens not in TOKENIZATIONS:
            raise ValueError(f"tokens must be one of {TOKENIZATIONS}, got {self.tokens!r}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (``type(config)(**config.to_dict())`` rebuilds it)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True, kw_only=True)
class TightConfig(EncoderSizes):
    """f2 (Sec. IV.A): 384 dimensions, 2 heads, 4 layers, dropout 0.1."""

    iter_max: int = 20  # k_max, SCvx iteration limit of the training data (Sec. IV.A: 20)

    def __post_init__(self) -> None:
        super().__post_init__()
        object.__setattr__(self, "iter_max", check_int("iter_max", self.iter_max, least=2))

    @property
    def n_rows(self) -> int:
        """R = 7 N."""
        return N_CONSTRAINT_NAMES * self.n_nodes


@dataclass(frozen=True, kw_only=True)
class SolutionConfig(EncoderSizes):
    """f1 (Sec. IV.A): 768 dimensions, 2 heads, 4 layers, dropout 0.1."""

    d_model: int = 768  # embedding width (larger than f2's: output 17 N + 1)

    @property
    def n_outputs(self) -> int:
        """17 N + 1: x (14 N), u (3 N), t_f."""
        return (STATE_DIM + CONTROL_DIM) * self.n_nodes + 1


@dataclass(frozen=True, kw_only=True)
class TscvxPreset:
    """Both networks' configurations."""

    tight: TightConfig
    solution: SolutionConfig


TSCVX_PRESETS: dict[str, TscvxPreset] = {
    # Sec. IV.A; PyTorch's default feed-forward width. With R = 7 N = 350 outputs f2 has
    # 8.82 M parameters (Table 3: 8.91 M with the paper's 12 N outputs); f1 has 22.7 M
    # (Table 3 says 9 M, which 768 dimensions and 4 layers cannot give: one 768-wide layer
    # alone has 5.5 M).
    "paper": TscvxPreset(tight=TightConfig(), solution=SolutionConfig()),
    # small: 2 layers, 64 (f2) / 128 (f1) dimensions, one token per input. Measured on the dev
    # set (29 solved instances x 8 rotations, 184 training samples, 9432 f2 items; 8 f2 and
    # 200 f1 epochs, one thread each, machine loaded ~6x): against ``single`` tokens,
    # ``inputs`` gave f2 validation accuracy 92.1 % vs 90.7 % (all zeros 90.2 %), precision
    # 0.56 vs 0.52, recall 0.84 vs 0.77, best validation BCE 0.431 vs 0.467, and f1
    # standardized MSE 1.00 vs 1.07, for 3.7x the f2 training time (135 s vs 37 s); both
    # infer in 0.2-0.3 ms at batch 1 on one thread (``scpformer bench tscvx``).
    "small": TscvxPreset(
        tight=TightConfig(d_model=64, n_head=2, n_layer=2, d_ff=128, tokens="inputs"),
        solution=SolutionConfig(d_model=128, n_head=2, n_layer=2, d_ff=256, tokens="inputs"),
    ),
}


# ======================================================================================
# the networks
# ======================================================================================
class TokenEncoder(nn.Module):
    """Linear encoder, learned position encoding, transformer encoder, linear decoder.

    ``forward(features (B, n_inputs)) -> (B, n_outputs)`` (Sec. III.D.1).
    """

    def __init__(self, sizes: EncoderSizes, n_inputs: int, n_outputs: int) -> None:
        super().__init__()
        self.tokens, d = sizes.tokens, sizes.d_model
        if self.tokens == "single":
            self.encode = nn.Linear(n_inputs, d)
            self.position = nn.Parameter(torch.zeros(1, 1, d))  # one token's position
        else:
            self.value_weight = nn.Parameter(torch.zeros(n_inputs, d))  # w_i
            self.position = nn.Parameter(torch.zeros(1, n_inputs + 1, d))  # b_i and read-out
        layer = nn.TransformerEncoderLayer(
            d, sizes.n_head, sizes.d_ff, sizes.dropout, batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, sizes.n_layer, enable_nested_tensor=False)
        self.decode = nn.Linear(d, n_outputs)
        if self.tokens == "inputs":  # token embeddings as nn.Embedding's: N(0, 1)
            nn.init.normal_(self.value_weight)
            nn.init.normal_(self.position)

    def forward(self, features: Tensor) -> Tensor:
        if self.tokens == "single":
            tokens = self.encode(features)[:, None, :] + self.position  # (B, 1, d)
        else:
            values = features[:, :, None] * self.value_weight  # (B, n_inputs, d)
            readout = torch.zeros_like(values[:, :1])  # (B, 1, d): the position alone
            tokens = torch.cat([values, readout], dim=1) + self.position  # (B, n_inputs + 1, d)
        hidden = self.encoder(tokens)  # (B, T, d)
        return self.decode(hidden[:, -1])  # (B, n_outputs): last token (the only, or read-out)


def iteration_feature(k: Tensor, iter_max: int) -> Tensor:
    """k in 1..iter_max -> ``2 (k - 1) / (iter_max - 1) - 1`` in [-1, 1] (float)."""
    return 2.0 * (k.to(torch.float32) - 1.0) / (iter_max - 1) - 1.0


class TightClassifier(nn.Module):
    """f2(theta, k): one tight-constraint logit per (name, node) row (Sec. III.C, III.D.1).

    ``forward(theta_std (B, 16), k (B,) int64) -> logits (B, R)``; ``sigmoid(logit) > 0.5``
    predicts the row tight at SCvx iteration k.
    """

    def __init__(self, config: TightConfig) -> None:
        super().__init__()
        if not isinstance(config, TightConfig):
            raise TypeError(f"config must be a TightConfig, got {type(config).__name__}")
        self.config = config
        self.net = TokenEncoder(config, N_THETA + 1, config.n_rows)

    def forward(self, theta_std: Tensor, k: Tensor) -> Tensor:
        _check_theta(theta_std)
        if k.shape != theta_std.shape[:1]:
            raise ValueError(f"k must be (B,) = {tuple(theta_std.shape[:1])}, got {tuple(k.shape)}")
        features = torch.cat([theta_std, iteration_feature(k, self.config.iter_max)[:, None]], 1)
        return self.net(features)  # (B, R)


class SolutionRegressor(nn.Module):
    """f1(theta): the standardized solution (x, u, t_f) (Sec. III.D, Algorithm 2 step input).

    ``forward(theta_std (B, 16)) -> (B, 17 N + 1)`` in the layout of the module docstring.
    """

    def __init__(self, config: SolutionConfig) -> None:
        super().__init__()
        if not isinstance(config, SolutionConfig):
            raise TypeError(f"config must be a SolutionConfig, got {type(config).__name__}")
        self.config = config
        self.net = TokenEncoder(config, N_THETA, config.n_outputs)

    def forward(self, theta_std: Tensor) -> Tensor:
        _check_theta(theta_std)
        return self.net(theta_std)  # (B, 17 N + 1)


def _check_theta(theta: Tensor) -> None:
    if theta.ndim != 2 or theta.shape[1] != N_THETA:
        raise ValueError(f"theta must be (B, {N_THETA}), got {tuple(theta.shape)}")


# ======================================================================================
# standardization (training split statistics) and the models API of the checkpoints
# ======================================================================================
@dataclass(frozen=True, kw_only=True, eq=False)
class TscvxNormalization:
    """Per-element training-split mean and std of theta, x, u and t_f (Sec. III.E.3).

    With ``canonical`` (not in the paper), the networks see every instance in its canonical
    frame (:mod:`scpformer.problems.pdg6dof.symmetry`: yawed about Up so that ``r0`` has no
    North component, the body rolled so that ``q0`` has no twist about body x, ``q0_w >= 0``)
    and the solution network predicts the solution in that frame; :meth:`decode_solution`
    maps it back. Both symmetries are exact for the problem, so the networks learn a function
    of two fewer inputs, without the sign ambiguity of ``q0``, and every rotated copy of the
    augmentation is the same training point. The statistics are then those of the canonical
    quantities. Checkpoints written before this option load with ``canonical = False``.
    """

    theta_mean: np.ndarray  # (16,)
    theta_std: np.ndarray  # (16,)
    x_mean: np.ndarray  # (N, 14)
    x_std: np.ndarray  # (N, 14)
    u_mean: np.ndarray  # (N, 3)
    u_std: np.ndarray  # (N, 3)
    tf_mean: float  # [U_T]
    tf_std: float  # [U_T]
    canonical: bool = False  # instances and solutions seen in their canonical frame

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            if f.name == "canonical":
                object.__setattr__(self, "canonical", bool(self.canonical))
                continue
            value = np.asarray(getattr(self, f.name), dtype=np.float64)
            if f.name.startswith("tf"):
                value = float(value)
            object.__setattr__(self, f.name, value)
        n = self.x_mean.shape[0] if self.x_mean.ndim == 2 else -1
        shapes = {"theta": (N_THETA,), "x": (n, STATE_DIM), "u": (n, CONTROL_DIM)}
        for key, shape in shapes.items():
            for part in ("mean", "std"):
                if getattr(self, f"{key}_{part}").shape != shape or n < 1:
                    raise ValueError(f"{key}_{part} must be {shape} with N >= 1")
        stds = [self.theta_std, self.x_std, self.u_std, np.array(self.tf_std)]
        if any(np.any(~(s > 0.0)) for s in stds):
            raise ValueError("standard deviations must be positive")

    @property
    def n_nodes(self) -> int:
        return self.x_mean.shape[0]

    @classmethod
    def from_splits(cls, splits: Splits) -> TscvxNormalization:
        """The statistics ``dataset split`` stored (training split, per element).

        The per-node std of x and u is floored at ``STEP_STD_FLOOR`` (0.1) times the
        element's std over all nodes, as ART's per-step statistics are
        (:func:`scpformer.models.normalization._per_step_floor`): some nodes are nearly
        deterministic (the final state, the thrust at the last node), and a ~0 std would let
        them dominate the standardized MSE and turn tiny errors into large ones.
        """
        missing = sorted({"theta", "x", "u", "tf"} - set(splits.stats))
        if missing:
            raise ValueError(f"the splits hold no training statistics of {missing}")
        s = splits.stats
        return cls(
            theta_mean=s["theta"].mean, theta_std=s["theta"].std,
            x_mean=s["x"].mean, x_std=_per_step_floor(s["x"].mean, s["x"].std),
            u_mean=s["u"].mean, u_std=_per_step_floor(s["u"].mean, s["u"].std),
            tf_mean=s["tf"].mean, tf_std=s["tf"].std,
        )  # fmt: skip

    @classmethod
    def canonical_from_arrays(
        cls, theta: np.ndarray, x: np.ndarray, u: np.ndarray, tf: np.ndarray
    ) -> TscvxNormalization:
        """Statistics of the canonical-frame training samples (theta (B, 16), x (B, N, 14),
        u (B, N, 3), tf (B,), raw), floored as :meth:`from_splits`'s; the two components that
        the canonical frame zeroes (``r0_N``, ``q0_x``) get std 1."""
        frame = sym.canonical_frame(theta)
        theta_c = sym.theta_to_canonical(theta, frame)
        x_c, u_c = sym.solution_to_canonical(x, u, frame)
        stats = {
            name: (value.mean(axis=0), _floored(value.std(axis=0)))
            for name, value in (("theta", theta_c), ("x", x_c), ("u", u_c))
        }
        return cls(
            theta_mean=stats["theta"][0], theta_std=stats["theta"][1],
            x_mean=stats["x"][0], x_std=_per_step_floor(*stats["x"]),
            u_mean=stats["u"][0], u_std=_per_step_floor(*stats["u"]),
            tf_mean=float(np.mean(tf)), tf_std=float(_floored(np.std(tf))),
            canonical=True,
        )  # fmt: skip

    def encode_theta(
        self, theta: np.ndarray, frame: sym.CanonicalFrame | None = None
    ) -> np.ndarray:
        """Raw theta (B, 16) -> standardized (in the canonical frame with ``canonical``;
        ``frame``: theta's :meth:`frame`, when the caller has it already)."""
        frame = self._frame_of("encode_theta", theta) if frame is None else frame
        if frame is not None:
            theta = sym.theta_to_canonical(theta, frame)
        return (theta - self.theta_mean) / self.theta_std

    def encode_solution(
        self, x: np.ndarray, u: np.ndarray, tf: np.ndarray, theta: np.ndarray | None = None
    ) -> np.ndarray:
        """(x (B, N, 14), u (B, N, 3), tf (B,)) -> standardized vector (B, 17 N + 1).

        ``theta`` (B, 16), the instances, is required with ``canonical``."""
        frame = self._frame_of("encode_solution", theta)
        if frame is not None:
            x, u = sym.solution_to_canonical(x, u, frame)
        b = len(tf)
        parts = [
            ((x - self.x_mean) / self.x_std).reshape(b, -1),
            ((u - self.u_mean) / self.u_std).reshape(b, -1),
            ((np.asarray(tf) - self.tf_mean) / self.tf_std)[:, None],
        ]
        return np.concatenate(parts, axis=1)

    def decode_solution(
        self,
        z: np.ndarray,
        theta: np.ndarray | None = None,
        frame: sym.CanonicalFrame | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Inverse of :meth:`encode_solution`: (B, 17 N + 1) -> x, u, tf (physical, in the
        instances' own frame; ``theta`` (B, 16), or its :meth:`frame`, is required with
        ``canonical``)."""
        frame = self._frame_of("decode_solution", theta) if frame is None else frame
        n, b = self.n_nodes, z.shape[0]
        x = z[:, : STATE_DIM * n].reshape(b, n, STATE_DIM) * self.x_std + self.x_mean
        u = z[:, STATE_DIM * n : -1].reshape(b, n, CONTROL_DIM) * self.u_std + self.u_mean
        if frame is not None:
            x, u = sym.solution_from_canonical(x, u, frame)
        return x, u, z[:, -1] * self.tf_std + self.tf_mean

    def frame(self, theta: np.ndarray) -> sym.CanonicalFrame | None:
        """The canonical frame of theta (B, 16), or None without ``canonical``."""
        return self._frame_of("frame", theta)

    def _frame_of(self, method: str, theta: np.ndarray | None) -> sym.CanonicalFrame | None:
        """The canonical frame of theta (B, 16), or None without ``canonical``."""
        if not self.canonical:
            return None
        if theta is None:
            raise ValueError(f"{method} of a canonical normalization needs theta")
        return sym.canonical_frame(theta)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TscvxNormalization:
        """Inverse of :meth:`to_dict`; a dict without ``canonical`` (written before that
        option existed) loads with ``canonical = False``."""
        known = {f.name for f in dataclasses.fields(cls)}
        if not known - {"canonical"} <= set(data) <= known:
            raise ValueError(f"normalization dict must have keys {sorted(known)}")
        return cls(**data)


def preset(kind: str, name: str, **overrides: Any) -> TightConfig | SolutionConfig:
    """The ``name`` preset's configuration of network ``kind`` (``tscvx-tight|solution``)."""
    _check_kind(kind)
    if name not in TSCVX_PRESETS:
        raise ValueError(f"preset must be one of {tuple(TSCVX_PRESETS)}, got {name!r}")
    base = TSCVX_PRESETS[name]
    config = base.tight if kind == TIGHT_KIND else base.solution
    return config_from_dict(kind, config.to_dict() | overrides)


def config_from_dict(kind: str, data: Mapping[str, Any]) -> TightConfig | SolutionConfig:
    """The configuration of ``kind`` from ``to_dict()`` output (unknown keys: ValueError)."""
    _check_kind(kind)
    cls = TightConfig if kind == TIGHT_KIND else SolutionConfig
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"unknown {cls.__name__} field(s) {unknown}; known: {sorted(known)}")
    return cls(**data)


def build_model(kind: str, config: TightConfig | SolutionConfig) -> nn.Module:
    """A freshly initialized network of ``kind``."""
    _check_kind(kind)
    return TightClassifier(config) if kind == TIGHT_KIND else SolutionRegressor(config)


def _check_kind(kind: str) -> None:
    if kind not in MODEL_KINDS:
        raise ValueError(f"kind must be one of {MODEL_KINDS}, got {kind!r}")


# The models API (scpformer.train.models_api) that training and checkpoints use for T-SCvx.
TSCVX_MODELS = SimpleNamespace(
    build_model=build_model,
    preset=preset,
    config_from_dict=config_from_dict,
    ArtNormalization=TscvxNormalization,  # the API's name for "the checkpoint's normalization"
    TRAIN_DEFAULTS=None,
    MODEL_KINDS=MODEL_KINDS,
)


# ======================================================================================
# the predictor (the solver's API)
# ======================================================================================
class TscvxPredictor:
    """Both trained networks behind raw-theta numpy calls (the T-SCvx contract).

    Parameters
    ----------
    tight, solution
        The trained f2 and f1 (eval mode).
    normalization
        Training-split statistics that standardize theta and de-standardize the solution.
    threshold
        Probability above which :meth:`predict_tight` calls a row tight.
    device
        Where the networks run.
    trace
        Let :meth:`warm_up` trace each network for batch-1 calls (one theta, as the solver
        asks) with ``torch.jit``, frozen: the same operations without the per-module Python
        dispatch. Measured with ``torch.set_num_threads(1)`` on the small preset (median of
        5 x 300 calls): f1 0.49 -> 0.26 ms, f2 0.39 -> 0.16 ms, outputs identical.
        Batches run eagerly; a network that fails to trace runs eagerly too.
        The trace freezes the weights it was made with: after changing a network's weights,
        build a new predictor (or pass ``trace=False``).
        ``torch.jit`` is deprecated in favour of ``torch.compile``/``torch.export``, but
        neither serves this case: ``export`` ran 0.71 ms against eager's 0.50 ms, and
        ``compile`` needs a C++ toolchain and seconds of compilation per process.
    """

    def __init__(
        self,
        tight: TightClassifier,
        solution: SolutionRegressor,
        normalization: TscvxNormalization,
        *,
        threshold: float = 0.5,
        device: str | torch.device = "cpu",
        trace: bool = True,
    ) -> None:
        if not 0.0 < threshold < 1.0:
            raise ValueError(f"threshold must be in (0, 1), got {shown(threshold)}")
        n = {tight.config.n_nodes, solution.config.n_nodes, normalization.n_nodes}
        if len(n) != 1:
            raise ValueError(f"the networks and the normalization disagree on N: {sorted(n)}")
        self.device = torch.device(device)
        self.tight = tight.to(self.device).eval()
        self.solution = solution.to(self.device).eval()
        self.normalization = normalization
        self.threshold = float(threshold)
        self.n_nodes = normalization.n_nodes  # N
        self.n_rows = tight.config.n_rows  # R = 7 N
        # the last theta's key, standardized input and canonical frame
        self._encoded: tuple[tuple, Tensor, sym.CanonicalFrame | None] | None = None
        self._trace = bool(trace)
        self._traced: dict[str, nn.Module] = {}  # network name -> its batch-1 trace

    def warm_up(self) -> None:
        """Trace both networks for batch-1 calls (with ``trace``) and run each once, so that
        the calls that follow, and their timings, do not pay for it.

        Until then every call runs eagerly: the first trace in a process costs about 0.7 s
        (torch.jit's own start-up), which a one-shot solve (0.5-1 s) should not pay. Long
        runs (the T-SCvx studies, ``scpformer bench tscvx``) warm up first.
        """
        theta = self.normalization.theta_mean.copy()
        theta[sym.THETA_Q] = (1.0, 0.0, 0.0, 0.0)  # a valid attitude for the canonical frame
        if self._trace:
            z, _, single = self._theta(theta)
            k = self._k(1, len(z), single)
            self._traced = {
                "tight": _batch_one_trace(self.tight, (z, k)),
                "solution": _batch_one_trace(self.solution, (z,)),
            }
        self.predict_solution(theta)
        self.predict_tight(theta, 1)
        self._encoded = None

    def _network(self, name: str, inputs: tuple[Tensor, ...]) -> nn.Module:
        """``self.tight`` or ``self.solution`` (``name``), or its batch-1 trace when
        :meth:`warm_up` made one and ``inputs`` are one theta."""
        traced = self._traced.get(name) if len(inputs[0]) == 1 else None
        return getattr(self, name) if traced is None else traced

    def _theta(self, theta: np.ndarray) -> tuple[Tensor, sym.CanonicalFrame | None, bool]:
        """Standardized (B, 16) float32 tensor, theta's canonical frame (None without
        ``canonical``), and whether ``theta`` was one vector."""
        theta = np.asarray(theta, dtype=np.float64)
        single = theta.ndim == 1
        if theta.ndim not in (1, 2) or theta.shape[-1] != N_THETA:
            raise ValueError(f"theta must be ({N_THETA},) or (B, {N_THETA}), got {theta.shape}")
        if not np.all(np.isfinite(theta)):
            raise ValueError("theta must be finite (it holds NaN or inf)")
        key = (theta.shape, theta.tobytes())
        if self._encoded is None or self._encoded[0] != key:  # T-SCvx asks once per iteration
            frame = self.normalization.frame(np.atleast_2d(theta))
            z = self.normalization.encode_theta(np.atleast_2d(theta), frame)
            tensor = torch.as_tensor(z, dtype=torch.float32, device=self.device)
            self._encoded = key, tensor, frame
        return self._encoded[1], self._encoded[2], single

    def _k(self, k: int | np.ndarray, batch: int, single: bool) -> Tensor:
        k_array = np.asarray(k)
        if k_array.dtype.kind not in "iu":
            raise TypeError(f"k must be an int or an integer array, got {k_array.dtype}")
        if k_array.ndim == 0:
            k_array = np.full(batch, int(k_array))
        elif single or k_array.shape != (batch,):
            raise ValueError(f"k must be an int or ({batch},) for this theta, got {k_array.shape}")
        if np.any(k_array < 1):
            raise ValueError(f"k must be >= 1 (1-based SCvx iteration), got min {k_array.min()}")
        return torch.as_tensor(k_array, dtype=torch.int64, device=self.device)

    @torch.inference_mode()
    def predict_tight_proba(self, theta: np.ndarray, k: int | np.ndarray) -> np.ndarray:
        """P(row tight at iteration k): (R,) for theta (16,), (B, R) for theta (B, 16)."""
        z, _, single = self._theta(theta)
        inputs = (z, self._k(k, len(z), single))
        logits = self._network("tight", inputs)(*inputs)  # (B, R)
        proba = torch.sigmoid(logits).cpu().numpy().astype(np.float64)
        return proba[0] if single else proba

    def predict_tight(
        self, theta: np.ndarray, k: int | np.ndarray, threshold: float | None = None
    ) -> np.ndarray:
        """Predicted tight flags (bool), shaped as :meth:`predict_tight_proba`."""
        cut = self.threshold if threshold is None else threshold
        return self.predict_tight_proba(theta, k) > cut

    @torch.inference_mode()
    def predict_solution(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, Any]:
        """(x (N, 14), u (N, 3), tf float) for theta (16,); (B, N, 14), (B, N, 3), (B,) for
        theta (B, 16). The quaternion is not normalized."""
        z, frame, single = self._theta(theta)
        out = self._network("solution", (z,))(z).cpu().numpy().astype(np.float64)
        x, u, tf = self.normalization.decode_solution(out, np.atleast_2d(theta), frame)
        return (x[0], u[0], float(tf[0])) if single else (x, u, tf)


def _batch_one_trace(network: nn.Module, inputs: tuple[Tensor, ...]) -> nn.Module:
    """``network`` traced and frozen for ``inputs`` of batch 1, or ``network`` itself when
    the tracer cannot record it (see ``trace`` in :class:`TscvxPredictor`)."""
    try:
        with torch.no_grad(), warnings.catch_warnings():
            warnings.simplefilter("ignore", torch.jit.TracerWarning)  # shape checks: constants
            warnings.simplefilter("ignore", DeprecationWarning)
            return torch.jit.freeze(torch.jit.trace(network, inputs))
    except Exception:  # an operation the tracer cannot record: stay eager
        return network


CHECKPOINT_CHOICES = {"best": "best.pt", "last": "checkpoint.pt"}


def load_tscvx_predictor(
    run_dir: Path | str,
    device: str | torch.device = "cpu",
    *,
    threshold: float = 0.5,
    checkpoint: str = "best",
    trace: bool = True,
) -> TscvxPredictor:
    """The predictor of run folder ``run_dir`` (``RUN/tight`` and ``RUN/solution``).

    ``checkpoint``: ``best`` (each network's epoch of least validation loss, ``best.pt``) or
    ``last`` (its last epoch, ``checkpoint.pt``). A packaged run
    (:mod:`scpformer.pretrained`) keeps one weights-only ``checkpoint.pt`` per network, made
    from ``best.pt``; ``best`` loads it when there is no ``best.pt``. ``trace``: see
    :class:`TscvxPredictor`.

    Raises
    ------
    CheckpointError
        (a ValueError) when a checkpoint is missing, unreadable, or of another model kind or
        family.
    """
    if checkpoint not in CHECKPOINT_CHOICES:
        raise ValueError(
            f"checkpoint must be one of {tuple(CHECKPOINT_CHOICES)}, got {checkpoint!r}"
        )
    run, file = Path(run_dir), CHECKPOINT_CHOICES[checkpoint]
    folders = {TIGHT_KIND: "tight", SOLUTION_KIND: "solution"}
    paths = {kind: run / folder / file for kind, folder in folders.items()}
    if checkpoint == "best":  # a packaged network keeps only checkpoint.pt (made from best.pt)
        last = CHECKPOINT_CHOICES["last"]
        paths = {kind: p if p.is_file() else p.with_name(last) for kind, p in paths.items()}
    loaded = {
        kind: load_checkpoint(path, kind=kind, family=FAMILY, models=TSCVX_MODELS)
        for kind, path in paths.items()
    }
    return TscvxPredictor(
        loaded[TIGHT_KIND].model,
        loaded[SOLUTION_KIND].model,
        loaded[SOLUTION_KIND].normalization,
        threshold=threshold,
        device=device,
        trace=trace,
    )
