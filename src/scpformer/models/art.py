"""ART, the Autonomous Rendezvous Transformer (ART paper Sec. 3, Fig. 2; robust ART Sec. 3).

A GPT over the token sequence of :mod:`scpformer.models.sequence`: per time step the
(optional) target state, reward-to-go, constraint-to-go, state and control, each through its
own linear encoder, plus a learned time-step embedding; pre-LayerNorm causal self-attention
blocks on ``torch.nn.functional.scaled_dot_product_attention``; linear decoders that predict
the control at the state token and the next state at the control token; the Eq. 8 loss with
teacher forcing.

Training (nanoGPT style)::

    predictions, loss = model(batch)  # batch: rtg, ctg (B,T,1), state (B,T,6), action (B,T,3)

Generation with a key-value cache (Algorithms 1-2), batched over instances; every call feeds
only the new tokens, the prefix is never recomputed::

    cache = model.start(batch_size, target=None)
    for i in range(N):
        u = model.predict_action(cache, rtg, ctg, x)  # feeds [g] R C x, returns u_hat(t_i)
        x_hat = model.predict_state(cache, u)  # feeds u, returns x_hat(t_{i+1}) (Alg. 1)
        # or model.feed_action(cache, u): u rides with the next step's tokens (Alg. 2)

Sizes: ``paper`` (Table 4) 6 layers, 6 heads, 384 dimensions, 10.7 M parameters; ``small``
3 layers, 3 heads, 96 dimensions, 0.35 M parameters (chosen by measuring, see ART_PRESETS).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn
from torch.nn import functional

from scpformer.models.capabilities import require_low_precision
from scpformer.models.sequence import (
    ACTIVATIONS,
    StepCache,
    TokenSequenceModel,
    activation_fn,
    check_sizes,
    init_weights,
    residual_std,
)
from scpformer.validation import shown_as

# Table 4's optimization settings, read by the trainer (scpformer.train); not model sizes.
TRAIN_DEFAULTS: dict[str, Any] = {
    "learning_rate": 3e-5,  # Table 4
    "grad_clip": 1.0,  # gradient norm clip (Table 4)
    "grad_accumulation": 8,  # gradient accumulation iterations (Table 4)
    "batch_size": 4,  # Table 4
    "lr_decay": None,  # learning rate decay: none (Table 4)
}


@dataclass(frozen=True, kw_only=True)
class ArtConfig:
    """Sizes of ART; the defaults are Table 4 of the ART paper (Table 3 of robust ART)."""

    n_layer: int = 6  # transformer blocks
    n_head: int = 6  # attention heads per block
    n_embd: int = 384  # embedding dimension C
    context: int = 100  # context length K [time steps]
    dropout: float = 0.1  # dropout probability on embeddings and residuals (training only)
    attn_dropout: float | None = None  # on attention weights; None = ``dropout`` (Table 4)
    activation: str = "relu"  # MLP non-linearity: relu (Table 4) or gelu
    state_dim: int = 6  # x: RTN [m, m/s] or ROE [m]
    action_dim: int = 3  # u: impulse dv in RTN [m/s]
    target_dim: int = 0  # g: target state token (6 for robust ART's five modalities)
    bias: bool = True  # biases in the linear layers and LayerNorms

    def __post_init__(self) -> None:
        check_sizes(self, n_head=(self.n_head, 1))
        if self.n_embd % self.n_head:
            raise ValueError(f"n_embd ({self.n_embd}) must be divisible by n_head ({self.n_head})")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {ACTIVATIONS}, got {self.activation!r}")
        if not isinstance(self.bias, bool):
            raise TypeError(f"bias must be a bool, got {type(self.bias).__name__}")
        attn = self.attn_dropout
        if attn is not None and (not isinstance(attn, int | float) or not 0.0 <= attn < 1.0):
            raise ValueError(
                f"attn_dropout must be None or in [0, 1), got {shown_as(attn, int | float)}"
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (``ArtConfig(**config.to_dict())`` rebuilds it)."""
        return dataclasses.asdict(self)


ART_PRESETS: dict[str, ArtConfig] = {
    # ART paper Table 4 (robust ART Table 3): 10.7 M parameters.
    "paper": ArtConfig(),
    # Sized by measuring on this project's shared 2-core AMD EPYC (benchmarks/art_presets.py:
    # training epoch of 5000 random 100-step sequences at batch 32 on 2 threads; the 100-step
    # cached rollout with the dynamics in the loop on 1 thread; CPU seconds of the process,
    # the machine being loaded 5-6x). Decision Transformer's gym size (3 layers, 128 dims) and
    # 4 x 128 cost 1.3-1.8x more per epoch (624 / 862 s vs 492 s) and reach 53-68 instead of
    # 90 trajectories/s at batch 64, whose key-value reads are memory-bound (their volume
    # scales with layers x width); 2 x 128 is as fast but shallower. 3 layers x 96 dims
    # (0.35 M parameters) keeps an epoch at ~8 CPU-minutes (the paper size: ~66).
    # small: no dropout on the attention weights. With it, PyTorch's CPU attention falls back
    # from the fused kernel to the math path and one training step takes 2.2x as long
    # (11 s vs 5 s for 32 sequences on this machine under load); dropout on the embeddings
    # and residuals stays.
    "small": ArtConfig(n_layer=3, n_head=3, n_embd=96, attn_dropout=0.0),
}


# ======================================================================================
# the transformer
# ======================================================================================
class CausalSelfAttention(nn.Module):
    """Multi-head causal self-attention with one fused query-key-value projection (Eq. 1)."""

    def __init__(self, config: ArtConfig) -> None:
        super().__init__()
        attn = config.dropout if config.attn_dropout is None else config.attn_dropout
        self.n_head, self.dropout = config.n_head, attn
        self.qkv = nn.Linear(config.n_embd, 3 * config.n_embd, bias=config.bias)
        self.proj = nn.Linear(config.n_embd, config.n_embd, bias=config.bias)
        self.resid_drop = nn.Dropout(config.dropout)

    def _heads(self, x: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        b, n, c = x.shape
        qkv = self.qkv(x).view(b, n, 3, self.n_head, c // self.n_head)  # (B, n, 3, h, d)
        return qkv.permute(2, 0, 3, 1, 4).unbind(0)  # 3 x (B, h, n, d)

    def _merge(self, y: Tensor) -> Tensor:
        b, _, n, _ = y.shape
        return self.resid_drop(self.proj(y.transpose(1, 2).reshape(b, n, -1)))  # (B, n, C)

    def forward(self, x: Tensor) -> Tensor:  # x: (B, L, C)
        q, k, v = self._heads(x)  # (B, h, L, d)
        p = self.dropout if self.training else 0.0
        y = functional.scaled_dot_product_attention(
            q, k, v, dropout_p=p, is_causal=True
        )  # (B,h,L,d)
        return self._merge(y)  # (B, L, C)


class MLP(nn.Module):
    """Position-wise feed-forward network, 4x wide (GPT)."""

    def __init__(self, config: ArtConfig) -> None:
        super().__init__()
        self.fc = nn.Linear(config.n_embd, 4 * config.n_embd, bias=config.bias)
        self.proj = nn.Linear(4 * config.n_embd, config.n_embd, bias=config.bias)
        self.act = activation_fn(config.activation)
        self.drop = nn.Dropout(config.dropout)

    def forward(self, x: Tensor) -> Tensor:  # (B, L, C)
        return self.drop(self.proj(self.act(self.fc(x))))  # (B, L, C)


class Block(nn.Module):
    """Pre-LayerNorm transformer block: ``x + attn(ln(x))``, then ``x + mlp(ln(x))``."""

    def __init__(self, config: ArtConfig) -> None:
        super().__init__()
        self.ln_1 = nn.LayerNorm(config.n_embd, bias=config.bias)
        self.attn = CausalSelfAttention(config)
        self.ln_2 = nn.LayerNorm(config.n_embd, bias=config.bias)
        self.mlp = MLP(config)

    def forward(self, x: Tensor) -> Tensor:  # (B, L, C)
        x = x + self.attn(self.ln_1(x))
        return x + self.mlp(self.ln_2(x))  # (B, L, C)


@dataclass(eq=False, kw_only=True)
class ArtCache(StepCache):
    """Queries, keys and values of a batch of generations, preallocated for ``max_steps`` steps.

    ``qkv[l]`` (3, B, h, L_max, d) holds block ``l``'s queries, keys and values of the
    ``length`` tokens fed so far, written by one copy per block and call; ``heads[l]`` are
    views of it with the batch and heads flattened: queries and values (B h, L_max, d) and
    the keys transposed (B h, d, L_max). ``mask`` (L_max, L_max) is the additive causal mask
    (0 or -inf), sliced for calls that feed several tokens.
    """

    qkv: list[Tensor]  # n_layer x (3, B, h, L_max, d)
    heads: list[tuple[Tensor, Tensor, Tensor]]  # views of qkv[l]: Q, K^T, V
    weights: list[tuple[Tensor | None, ...]]  # per block: the 12 tensors _feed reads
    linear: Callable[[Tensor, Tensor, Tensor | None], Tensor]  # x W^T + b with weights[l]
    linear_act: Callable[[Tensor, Tensor, Tensor | None], Tensor]  # act(x W^T + b), MLP in
    mask: Tensor  # (L_max, L_max) additive causal mask
    no_mask: Tensor  # (1, 1) zero: the mask of a last row, which sees every key
    length: int = 0  # tokens fed through the blocks


class ART(TokenSequenceModel):
    """The Autonomous Rendezvous Transformer (see the module docstring)."""

    def __init__(self, config: ArtConfig) -> None:
        super().__init__(config, ArtConfig)
        self.blocks = nn.ModuleList(Block(config) for _ in range(config.n_layer))
        self.ln_f = nn.LayerNorm(config.n_embd, bias=config.bias)
        self.apply(init_weights)
        for name, p in self.named_parameters():
            if name.endswith("proj.weight"):
                nn.init.normal_(p, mean=0.0, std=residual_std(config.n_layer))

        self._act = activation_fn(config.activation)

    def _weights(self, block: Block, batch_size: int, weights: str) -> tuple:
        """A block's 12 tensors in :meth:`_feed`'s order, in the layout of ``weights``.

        ``plain``: the linear weights transposed, contiguous (for ``addmm``: ~10 % faster
        than on a transposed view for the few-row products of the small preset);
        ``float32`` / ``bfloat16``: packed for oneDNN's product with ``4 batch_size`` rows;
        ``int8``: quantized and packed for ``linear_dynamic`` with the bias inside. The
        copies are made again only when a weight or bias changed since (in-place updates
        bump their version).
        """
        tensors = _block_weights(block)
        out = list(tensors)
        for i in (2, 4, 8, 10):  # qkv, attention proj, fc, mlp proj weights
            weight, bias = tensors[i], tensors[i + 1]
            packs = _packs_of(weight)
            key = (weights, batch_size)
            version = (weight._version, -1 if bias is None else bias._version)
            found, pack = packs.get(key, (None, None))
            if found != version:
                pack = _pack(weight.detach(), bias, weights, batch_size)
                packs[key] = (version, pack)
            out[i] = pack
            if weights == "int8":
                out[i + 1] = None  # inside the pack
            elif bias is not None and weights == "bfloat16":
                out[i + 1] = bias.detach().to(torch.bfloat16)
        return tuple(out)

    def _core(self, tokens: Tensor) -> Tensor:  # (B, L, C)
        for block in self.blocks:
            tokens = block(tokens)
        return self.ln_f(tokens)  # (B, L, C)

    def _empty_cache(
        self, batch_size: int, max_steps: int, target: Tensor | None, weights: str
    ) -> ArtCache:
        cfg = self.config
        length = max_steps * self.codec.tokens_per_step
        param = self.ln_f.weight
        d = cfg.n_embd // cfg.n_head
        cpu = param.device.type == "cpu"
        onednn = cpu and onednn_available()
        low = {"bfloat16": "bf16", "int8": "int8"}.get(weights)
        if low is not None and not cpu:
            raise ValueError(f"{low} generation runs on the CPU only, not on {param.device}")
        if low is not None:  # the kernels of this CPU, tried once (models.capabilities)
            require_low_precision(low)
        if weights == "float32" and not (onednn and (cfg.n_embd >= 256 or batch_size >= 8)):
            weights = "plain"
        packed = [self._weights(b, batch_size, weights) for b in self.blocks]
        linear = {
            "plain": transposed_linear,
            "float32": packed_linear,
            "bfloat16": packed_linear_bf16,
            "int8": quantized_linear,
        }[weights]
        act = self._act
        if cfg.activation == "relu" and weights in ("float32", "bfloat16"):  # oneDNN post-op
            linear_act = functools.partial(linear, activation="relu")
        elif cfg.activation == "relu":
            linear_act = lambda x, w, b: torch.relu_(linear(x, w, b))  # noqa: E731
        else:
            linear_act = lambda x, w, b: act(linear(x, w, b))  # noqa: E731
        qkv = [param.new_empty(3, batch_size, cfg.n_head, length, d) for _ in self.blocks]
        heads = [tuple(t.view(-1, length, d) for t in block) for block in qkv]
        return ArtCache(
            qkv=qkv,
            heads=[(q, k.transpose(1, 2), v) for q, k, v in heads],
            weights=packed,
            linear=linear,
            linear_act=linear_act,
            mask=causal_mask(length, param.dtype, param.device),  # (L, L)
            no_mask=param.new_zeros(1, 1),
            target=target,
            batch_size=batch_size,
            max_steps=max_steps,
        )

    def _feed(self, cache: ArtCache, x: Tensor) -> Tensor:
        """Run new tokens (B, n, C) through the blocks; the last one's output (B, C).

        The eager inference path, cut to few operations per block: functional calls on the
        weights gathered by :meth:`_empty_cache`; the new queries, keys and values written
        into the cache by one copy; attention written out as ``softmax(q K^T / sqrt(d) +
        mask) V`` over the cached keys with one ``baddbmm`` (for a few query rows several
        times faster than ``scaled_dot_product_attention`` on the CPU); the last block
        computed for the last token only (the other tokens' outputs are never read; their
        keys and values are). About 80 operator calls per Algorithm 2 step for three blocks
        (~140 before these cuts), which at a few microseconds each is most of the small
        preset's time at batch 1; the paper preset's is its 43 MB of float32 weights read
        once per step (``start(bf16=True)`` / ``start(int8=True)`` read a half / a quarter).

        Measured and not used: ``torch.compile`` of this loop (fixed shapes, full-length
        masked attention) took 29 s to compile and ran no faster than eager (24.5 vs 22.3
        ms per 100 small-preset steps, one thread, loaded machine); ``torch.jit.script`` is
        deprecated in this PyTorch.
        """
        b, n, c = x.shape
        start = cache.length
        end = start + n
        h = self.config.n_head
        d = c // h
        scale = d**-0.5
        mask = cache.mask[start:end, :end]  # (n, end)
        eps, last = self.ln_f.eps, len(cache.weights) - 1
        linear, linear_act = cache.linear, cache.linear_act
        x = x.reshape(b * n, c)  # rows: (batch, token)
        for layer, (w, qkv, (queries, keys_t, values)) in enumerate(
            zip(cache.weights, cache.qkv, cache.heads, strict=True)
        ):
            hid = torch.layer_norm(x, (c,), w[0], w[1], eps)
            qkv[:, :, :, start:end] = (
                linear(hid, w[2], w[3]).view(b, n, 3, h, d).permute(2, 0, 3, 1, 4)
            )  # (3, B, h, n, d)
            if layer == last:  # only the last token's output is read
                x, mask, q = x[n - 1 :: n], cache.no_mask, queries[:, end - 1 : end]
            else:
                q = queries[:, start:end]  # (B h, n', d)
            scores = torch.baddbmm(mask, q, keys_t[:, :, :end], alpha=scale)
            y = torch.bmm(torch.softmax(scores, dim=-1), values[:, :end])  # (B h, n', d)
            if y.shape[1] > 1:
                y = y.view(b, h, -1, d).transpose(1, 2)  # (B, n', h, d)
            x = x + linear(y.reshape(-1, c), w[4], w[5])  # (B n', C)
            hid = linear_act(torch.layer_norm(x, (c,), w[6], w[7], eps), w[8], w[9])
            x = x + linear(hid, w[10], w[11])  # (B n', C)
        cache.length = end
        return torch.layer_norm(x, (c,), self.ln_f.weight, self.ln_f.bias, eps)  # (B, C)


def _block_weights(block: Block) -> tuple[Tensor | None, ...]:
    """The tensors of one block in the order :meth:`ART._feed` reads them."""
    layers = (
        block.ln_1,
        block.attn.qkv,
        block.attn.proj,
        block.ln_2,
        block.mlp.fc,
        block.mlp.proj,
    )
    return tuple(t for layer in layers for t in (layer.weight, layer.bias))


# Packed copies of generation weights: id(weight) -> {(format, batch size): ((weight, bias)
# versions, pack)}; kept outside the modules (state dicts, pickles and copies of a model
# never carry them) and dropped when the weight is freed.
_PACKS: dict[int, dict[tuple[str, int], tuple[tuple[int, int], Any]]] = {}


def _packs_of(weight: Tensor) -> dict[tuple[str, int], tuple[tuple[int, int], Any]]:
    key = id(weight)
    if key not in _PACKS:
        _PACKS[key] = {}
        weakref.finalize(weight, _PACKS.pop, key, None)
    return _PACKS[key]


def onednn_available() -> bool:
    """Whether generation can run its linear layers on oneDNN with prepacked weights.

    It does so for wide layers or batches (``n_embd >= 256 or batch >= 8``): measured on
    this project's AMD EPYC (one thread, cached 100-step rollouts, CPU time), the packed
    oneDNN product is ~1.6x faster than the default (MKL) for the paper size at batch 1 and
    ~1.2x at batch 64 of a 128-wide model, but slower for 128-wide layers at batch 1.
    """
    return torch.backends.mkldnn.is_available() and hasattr(torch.ops.mkldnn, "_linear_pointwise")


def transposed_linear(x: Tensor, weight_t: Tensor, bias: Tensor | None) -> Tensor:
    """``x W^T + b`` for 2-D ``x`` with ``weight_t = W^T`` (one ``addmm``, no transpose)."""
    return torch.mm(x, weight_t) if bias is None else torch.addmm(bias, x, weight_t)


@functools.lru_cache(maxsize=8)
def causal_mask(length: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    """The additive causal mask (length, length): 0 on and below the diagonal, -inf above.

    Shared by every generation of that length (read only).
    """
    return torch.full((length, length), float("-inf"), dtype=dtype, device=device).triu(1)


_DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16}


def _pack(weight: Tensor, bias: Tensor | None, weights: str, batch_size: int) -> Tensor:
    """``weight`` (out, in) in the layout of ``weights`` (see :meth:`ART._weights`).

    The bfloat16 and int8 layouts need CPU kernels that not every x86-64 CPU has: callers
    check :func:`scpformer.models.capabilities.require_low_precision` first (``start`` does),
    which tries this function once on a tiny layer.
    """
    if weights == "plain":
        return weight.t().contiguous()  # (in, out)
    if weights != "int8":
        return torch.ops.mkldnn._reorder_linear_weight(weight.to(_DTYPES[weights]), 4 * batch_size)
    scale = weight.abs().amax(dim=1).clamp_min(1e-12).double() / 127.0  # per output channel
    zero = torch.zeros(weight.shape[0], dtype=torch.long)
    with warnings.catch_warnings():  # quantized tensors are deprecated in favour of torchao
        warnings.simplefilter("ignore")
        quantized = torch.quantize_per_channel(weight, scale, zero, 0, torch.qint8)
        return torch.ops.quantized.linear_prepack(
            quantized, None if bias is None else bias.detach()
        )


def quantized_linear(x: Tensor, pack: Tensor, bias: None) -> Tensor:
    """``x W^T + b`` with ``W`` in int8 per output channel and ``b`` in ``pack``
    (:func:`_pack`); ``x`` is quantized per call to uint8 over its own range (7 bits:
    ``reduce_range``, which keeps fbgemm's 16-bit intermediate sums from saturating)."""
    return torch.ops.quantized.linear_dynamic(x, pack, True)


def packed_linear(
    x: Tensor, weight: Tensor, bias: Tensor | None, activation: str = "none"
) -> Tensor:
    """``x W^T + b`` with ``W`` prepacked by ``torch.ops.mkldnn._reorder_linear_weight``,
    then ``activation`` (``none`` or ``relu``, fused into oneDNN's product)."""
    return torch.ops.mkldnn._linear_pointwise(x, weight, bias, activation, [], "")


def packed_linear_bf16(
    x: Tensor, weight: Tensor, bias: Tensor | None, activation: str = "none"
) -> Tensor:
    """:func:`packed_linear` with bfloat16 weights; ``x`` and the result stay float32."""
    out = torch.ops.mkldnn._linear_pointwise(x.bfloat16(), weight, bias, activation, [], "")
    return out.float()
