"""The token sequence every ART-style model reads, and the Eq. 8 loss they all train on.

Notation (ART paper Sec. 3, robust ART paper Sec. 3)
-----------------------------------------------------
One time step ``t_i`` of a trajectory is a group of tokens, in this order::

    [g]  R(t_i)  C(t_i)  x(t_i)  u(t_i)

``g`` is the target state (the robust paper's fifth modality, present when
``target_dim > 0``), ``R`` the reward-to-go (Eq. 4), ``C`` the constraint-to-go (Eq. 5),
``x`` the state and ``u`` the control. Each modality has its own linear encoder to the
embedding width ``C``; a learned embedding of the time step ``i`` is added to every token of
the step. Two linear decoders read the sequence model's output: the control ``u(t_i)`` is
predicted at the state token ``x(t_i)`` (Eq. 8, ``u_hat = ART(tau_<t_i, x(t_i))``) and the
next state ``x(t_{i+1})`` at the control token ``u(t_i)`` (``x_hat = ART(tau_<t_{i+1})``).

The transformer (:mod:`scpformer.models.art`) and the recurrent baselines
(:mod:`scpformer.models.rnn`) share this module, so that the three differ only in the core
that mixes the tokens.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import torch
from torch import Tensor, nn
from torch.nn import functional

from scpformer.validation import check_int, shown_as

ACTIVATIONS = ("relu", "gelu")


def check_sizes(config: object, **extra: tuple[int, int]) -> None:
    """Raise ``ValueError`` naming the field when a size of ``config`` is out of range.

    Checks ``n_layer, n_embd, context, state_dim, action_dim`` (>= 1), ``target_dim`` (>= 0),
    ``dropout`` in [0, 1), and every ``extra`` field ``name=(value, minimum)``. Each checked
    size is stored back on the (frozen) ``config`` as a Python int, so that a numpy integer
    leaves ``to_dict`` JSON-ready. A size that is not an integer raises
    :class:`~scpformer.validation.ArgumentTypeError` (a ``TypeError``).
    """
    limits = {
        "n_layer": 1,
        "n_embd": 1,
        "context": 1,
        "state_dim": 1,
        "action_dim": 1,
        "target_dim": 0,
    }
    checks = {name: (getattr(config, name), low) for name, low in limits.items()}
    for name, (value, low) in {**checks, **extra}.items():
        object.__setattr__(config, name, check_int(name, value, least=low))
    dropout = config.dropout
    if not isinstance(dropout, int | float) or not 0.0 <= dropout < 1.0:
        raise ValueError(f"dropout must be in [0, 1), got {shown_as(dropout, int | float)}")


def _inference(method: Callable) -> Callable:
    """``method`` under ``torch.no_grad()``, entered only when gradients are on (generation
    calls it a few hundred times per trajectory; the context costs microseconds)."""

    @functools.wraps(method)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if torch.is_grad_enabled():
            with torch.no_grad():
                return method(*args, **kwargs)
        return method(*args, **kwargs)

    return wrapper


class TokenCodec(nn.Module):
    """Modality encoders, time-step embedding and the two decoders (ART paper, Fig. 2).

    Parameters
    ----------
    n_embd
        Embedding width ``C``.
    context
        Largest number of time steps (rows of the time-step embedding).
    state_dim, action_dim, target_dim
        Sizes of ``x``, ``u`` and the target ``g`` (0: no target token).
    """

    def __init__(
        self, *, n_embd: int, context: int, state_dim: int, action_dim: int, target_dim: int
    ) -> None:
        super().__init__()
        self.state_dim, self.action_dim, self.target_dim = state_dim, action_dim, target_dim
        self.context = context
        self.embed_time = nn.Embedding(context, n_embd)
        self.embed_rtg = nn.Linear(1, n_embd)
        self.embed_ctg = nn.Linear(1, n_embd)
        self.embed_state = nn.Linear(state_dim, n_embd)
        self.embed_action = nn.Linear(action_dim, n_embd)
        self.embed_target = nn.Linear(target_dim, n_embd) if target_dim else None
        self.predict_action = nn.Linear(n_embd, action_dim)  # read at the x token
        self.predict_state = nn.Linear(n_embd, state_dim)  # read at the u token

    @property
    def tokens_per_step(self) -> int:
        """4, or 5 with the target token."""
        return 5 if self.target_dim else 4

    @property
    def state_slot(self) -> int:
        """Position of the x token inside a step's group."""
        return self.tokens_per_step - 2

    def embed_sequence(self, batch: Mapping[str, Tensor]) -> Tensor:
        """All tokens of ``batch`` interleaved step by step, (B, T k, C), ``k`` per step."""
        state = batch["state"]  # (B, T, s)
        b, t = state.shape[:2]
        groups = [
            self.embed_rtg(batch["rtg"]),  # (B, T, C)
            self.embed_ctg(batch["ctg"]),  # (B, T, C)
            self.embed_state(state),  # (B, T, C)
            self.embed_action(batch["action"]),  # (B, T, C)
        ]
        if self.embed_target is not None:
            groups.insert(0, self.embed_target(self.target_sequence(batch["target"], t)))
        steps = torch.arange(t, device=state.device)
        tokens = torch.stack(groups, dim=2) + self.embed_time(steps)[:, None]  # (B, T, k, C)
        return tokens.reshape(b, t * self.tokens_per_step, -1)  # (B, T k, C)

    @staticmethod
    def target_sequence(target: Tensor, t: int) -> Tensor:
        """The target as (B, T, g): a (B, g) target is repeated at every step."""
        return target[:, None].expand(-1, t, -1) if target.dim() == 2 else target

    @torch.no_grad()
    def step_codec(self, max_steps: int) -> StepCodec:
        """Every encoder and the time-step embedding of generation as one product per call.

        The tokens that one generation call feeds, ``[u(t_{i-1})] [g] R(t_i) C(t_i) x(t_i)``,
        are ``bias[i] + [u, g, R, C, x] W`` with ``W`` the block-diagonal stack of the
        encoders' (transposed) weights and ``bias[i]`` their biases plus the time-step
        embeddings of ``i - 1`` (the control token) and ``i`` (the others): the same tokens
        as :meth:`embed_sequence`, up to float rounding, in one ``addmm`` instead of one
        linear layer per modality.
        """
        encoders = [self.embed_action, self.embed_rtg, self.embed_ctg, self.embed_state]
        if self.embed_target is not None:
            encoders.insert(1, self.embed_target)
        c = self.embed_time.weight.shape[1]
        widths = [e.in_features for e in encoders]
        weight = self.embed_time.weight.new_zeros(sum(widths), c * len(encoders))
        row = 0
        for j, (encoder, width) in enumerate(zip(encoders, widths, strict=True)):
            weight[row : row + width, j * c : (j + 1) * c] = encoder.weight.T
            row += width
        time = self.embed_time.weight[:max_steps]  # (N, C)
        action_bias = self.embed_action.bias + time  # (N, C): the control token of step i
        step_bias = torch.cat([e.bias + time for e in encoders[1:]], dim=1)  # (N, (k-1) C)
        previous = torch.cat([action_bias[:1], action_bias[:-1]])  # row i: u(t_{i-1})
        return StepCodec(
            weight=weight,
            bias=torch.cat([previous, step_bias], dim=1),  # (N, k C)
            action_bias=action_bias,
            action_dim=self.action_dim,
            n_embd=c,
            decoder=(self.predict_action.weight.T, self.predict_action.bias),
        )

    def decode_sequence(self, hidden: Tensor) -> dict[str, Tensor]:
        """Predictions from the core's output (B, T k, C) (see the module docstring)."""
        b, length, c = hidden.shape
        steps = hidden.reshape(b, length // self.tokens_per_step, self.tokens_per_step, c)
        at_state = steps[:, :, self.state_slot]  # (B, T, C)
        at_action = steps[:, :-1, self.state_slot + 1]  # (B, T-1, C)
        return {
            "action": self.predict_action(at_state),  # (B, T, a)
            "state": self.predict_state(at_action),  # (B, T-1, s)
        }

    def check_batch(self, batch: Mapping[str, Tensor]) -> tuple[int, int]:
        """(B, T) of a training batch; ``ValueError`` naming the key on a bad shape."""
        if "state" not in batch:
            raise ValueError("batch must hold 'state' (B, T, state_dim)")
        state = batch["state"]
        if state.dim() != 3:
            wanted = f"(B, T, {self.state_dim})"
            raise ValueError(f"batch['state'] must be {wanted}, got {_shape(state)}")
        b, t = state.shape[:2]
        if t > self.context:
            raise ValueError(f"sequence of {t} steps is longer than the context {self.context}")
        wanted = {
            "rtg": (b, t, 1),
            "ctg": (b, t, 1),
            "state": (b, t, self.state_dim),
            "action": (b, t, self.action_dim),
        }
        for key, shape in wanted.items():
            if key not in batch:
                raise ValueError(f"batch must hold {key!r} {shape}")
            if tuple(batch[key].shape) != shape:
                raise ValueError(f"batch[{key!r}] must be {shape}, got {_shape(batch[key])}")
        self._check_target(batch.get("target"), b, t)
        mask = batch.get("mask")
        if mask is not None and (mask.dtype != torch.bool or tuple(mask.shape) != (b, t)):
            raise ValueError(f"batch['mask'] must be bool ({b}, {t}), got {_shape(mask)}")
        return b, t

    def _check_target(self, target: Tensor | None, b: int, t: int) -> None:
        if not self.target_dim:
            if target is not None:
                raise ValueError("batch holds 'target' but the model has target_dim = 0")
            return
        shapes = ((b, self.target_dim), (b, t, self.target_dim))
        if target is None or tuple(target.shape) not in shapes:
            got = "nothing" if target is None else _shape(target)
            raise ValueError(f"batch['target'] must be {shapes[0]} or {shapes[1]}, got {got}")


@dataclass(frozen=True, kw_only=True)
class StepCodec:
    """The encoders of one generation step as one product (:meth:`TokenCodec.step_encoder`).

    ``weight`` (a + g + 2 + s, k C) is block-diagonal; ``bias`` (N, k C) row ``i`` holds the
    encoders' biases plus the time-step embeddings of the tokens ``u(t_{i-1})`` and ``[g] R C
    x(t_i)``; ``action_bias`` (N, C) row ``i`` is the control token's bias at step ``i``.
    """

    weight: Tensor  # (a + g + 2 + s, k C)
    bias: Tensor  # (N, k C)
    action_bias: Tensor  # (N, C)
    action_dim: int  # a
    n_embd: int  # C
    decoder: tuple[Tensor, Tensor]  # the control decoder's W^T (C, a) and bias (a,)
    rows: tuple[tuple[Tensor, ...], tuple[Tensor, ...]] = ()  # bias, action_bias per step

    def __post_init__(self) -> None:  # per-step views, made once (one index op less a call)
        object.__setattr__(self, "rows", (self.bias.unbind(0), self.action_bias.unbind(0)))

    def step_tokens(self, step: int, inputs: list[Tensor], with_action: bool) -> Tensor:
        """The tokens of ``inputs`` ([u], [g], R, C, x: (B, width) each) as (B, n, C)."""
        z = torch.cat(inputs, dim=1)  # (B, m)
        if with_action:
            tokens = torch.addmm(self.rows[0][step], z, self.weight)
        else:
            a, c = self.action_dim, self.n_embd
            tokens = torch.addmm(self.bias[step, c:], z, self.weight[a:, c:])
        return tokens.view(z.shape[0], -1, self.n_embd)  # (B, n, C)

    def decode_action(self, hidden: Tensor) -> Tensor:
        """``u_hat`` (B, a) from the output (B, C) at the state token."""
        weight_t, bias = self.decoder
        return torch.addmm(bias, hidden, weight_t)

    def action_token(self, step: int, action: Tensor) -> Tensor:
        """The control token ``u(t_step)`` (B, a) as (B, 1, C)."""
        a, c = self.action_dim, self.n_embd
        return torch.addmm(self.rows[1][step], action, self.weight[:a, :c])[:, None]


@dataclass(eq=False, kw_only=True)
class StepCache:
    """Where a batch of generations stands: step ``i``, and which token comes next.

    Subclasses add the model's memory (keys and values for ART, hidden states for RNNs).
    """

    batch_size: int
    max_steps: int  # time steps the generation may take
    target: Tensor | None  # (B, g) normalized target state g (None without one)
    step_codec: StepCodec | None = None  # encoders as one product, decoder (set by start)
    step: int = 0  # time step i of the next R, C, x tokens
    awaiting_action: bool = False  # predict_action done, control token not given yet
    pending: Tensor | None = None  # (B, a) normalized control staged by feed_action


class TokenSequenceModel(nn.Module):
    """Training and generation interface shared by ART and the recurrent baselines.

    The constructor checks the configuration's type and builds the :class:`TokenCodec`
    (``self.codec``) and the embedding dropout (``self.drop``); subclasses implement
    ``_core(tokens) -> (B, L, C)`` (the whole sequence, training), ``_empty_cache`` and
    ``_feed(cache, tokens) -> (B, C)`` (new tokens only, generation).
    """

    def __init__(self, config: object, config_type: type) -> None:
        super().__init__()
        if not isinstance(config, config_type):
            raise TypeError(
                f"config must be an {config_type.__name__}, got {type(config).__name__}"
            )
        self.config = config
        self.codec = TokenCodec(
            n_embd=config.n_embd,
            context=config.context,
            state_dim=config.state_dim,
            action_dim=config.action_dim,
            target_dim=config.target_dim,
        )
        self.drop = nn.Dropout(config.dropout)

    def num_parameters(self) -> int:
        """Number of trainable parameters."""
        return sum(p.numel() for p in self.parameters())

    def forward(self, batch: Mapping[str, Tensor]) -> tuple[dict[str, Tensor], Tensor]:
        """Teacher-forced predictions of every control and next state, and the Eq. 8 loss.

        Parameters
        ----------
        batch
            Normalized ``rtg``, ``ctg`` (B, T, 1), ``state`` (B, T, s), ``action`` (B, T, a);
            ``target`` (B, g) or (B, T, g) when ``target_dim > 0``; optional ``mask`` (B, T)
            bool of valid steps (padding at the end).

        Returns
        -------
        predictions, loss
            ``{"action": (B, T, a), "state": (B, T-1, s)}`` (``state[:, i]`` predicts
            ``x(t_{i+1})``) and the scalar Eq. 8 loss.
        """
        self.codec.check_batch(batch)
        hidden = self._core(self.drop(self.codec.embed_sequence(batch)))  # (B, T k, C)
        predictions = self.codec.decode_sequence(hidden)
        return predictions, eq8_loss(predictions, batch)

    def _core(self, tokens: Tensor) -> Tensor:
        raise NotImplementedError

    def _empty_cache(
        self, batch_size: int, max_steps: int, target: Tensor | None, weights: str
    ) -> StepCache:
        raise NotImplementedError

    def _feed(self, cache: StepCache, tokens: Tensor) -> Tensor:
        raise NotImplementedError

    # -- generation (Algorithms 1-2), batched, each call feeds only new tokens ---------------
    @torch.no_grad()
    def start(
        self,
        batch_size: int,
        target: Tensor | None = None,
        *,
        max_steps: int | None = None,
        bf16: bool = False,
        int8: bool = False,
    ) -> StepCache:
        """An empty cache for ``batch_size`` generations of at most ``max_steps`` steps.

        ``target`` (B, g) is the normalized target state, required when ``target_dim > 0``.
        ``max_steps`` defaults to the context length (fewer steps need less memory).
        ``bf16`` multiplies by bfloat16 copies of the weights (ART on oneDNN only: about half
        the weight traffic, relative error of the order of 1e-3 per call); ``int8`` by int8
        copies quantized per output channel, the activations quantized per call (ART only:
        a quarter of the weight traffic, relative error of the order of 1e-2 per call).
        Both are approximations of the float32 model, off by default: in Algorithm 2's
        closed loop the errors grow (trained small preset, 20 sampled rendezvous: controls
        off by 1.1e-2 median / 3.6e-2 max with bf16, 5.6e-2 / 0.62 with int8, whose
        trajectory cost changed by up to 28 %); ``scpformer bench art --bf16 --int8``
        prints the error beside the time. Not every x86-64 CPU runs these kernels: where this
        one does not, both raise ``LowPrecisionUnavailableError`` (a ``ValueError``; see
        :mod:`scpformer.models.capabilities`).
        """
        context = self.codec.context
        max_steps = context if max_steps is None else max_steps
        batch_size = check_int("batch_size", batch_size, least=1)
        max_steps = check_int("max_steps", max_steps, least=1, most=context)
        if bf16 and int8:
            raise ValueError("bf16 and int8 exclude each other: choose one weight format")
        self._check_target(target, batch_size)
        weights = "bfloat16" if bf16 else "int8" if int8 else "float32"
        cache = self._empty_cache(batch_size, max_steps, target, weights)
        cache.step_codec = self.codec.step_codec(max_steps)
        return cache

    def _check_target(self, target: Tensor | None, batch_size: int) -> None:
        g = self.codec.target_dim
        if not g:
            if target is not None:
                raise ValueError("target given but the model has target_dim = 0")
            return None
        if target is None or tuple(target.shape) != (batch_size, g):
            got = "nothing" if target is None else _shape(target)
            raise ValueError(f"target must be ({batch_size}, {g}), got {got}")

    @_inference
    def predict_action(self, cache: StepCache, rtg: Tensor, ctg: Tensor, state: Tensor) -> Tensor:
        """Feed step i's [g] R C x tokens in one call; return ``u_hat(t_i)`` (B, a).

        ``rtg``, ``ctg`` (B, 1) and ``state`` (B, s) are normalized; ``cache`` is updated. A
        control token staged by :meth:`feed_action` goes through in the same call.
        """
        i = cache.step
        if cache.awaiting_action:
            raise ValueError("predict_action called twice: give the control with predict_state")
        if i >= cache.max_steps:
            raise ValueError(f"the cache holds {cache.max_steps} steps; start a new one")
        inputs = [rtg, ctg, state]
        if cache.target is not None:
            inputs.insert(0, cache.target)
        pending = cache.pending is not None
        if pending:
            inputs.insert(0, cache.pending)
        new = cache.step_codec.step_tokens(i, inputs, pending)  # (B, n, C)
        cache.pending, cache.awaiting_action = None, True
        return cache.step_codec.decode_action(self._feed(cache, new))  # (B, a)

    @_inference
    def predict_state(self, cache: StepCache, action: Tensor) -> Tensor:
        """Feed step i's control token ``u(t_i)`` (B, a); return ``x_hat(t_{i+1})`` (B, s)."""
        self.feed_action(cache, action)
        token = cache.step_codec.action_token(cache.step - 1, cache.pending)  # (B, 1, C)
        cache.pending = None
        return self.codec.predict_state(self._feed(cache, token))  # (B, s)

    @_inference
    def feed_action(self, cache: StepCache, action: Tensor) -> None:
        """Stage step i's control token ``u(t_i)`` (B, a) without predicting the next state.

        Algorithm 2 (dynamics in the loop) reads no ``x_hat``: the staged token goes through
        the network with the next step's tokens, one pass per step instead of two, with the
        same results as :meth:`predict_state`.
        """
        if not cache.awaiting_action:
            raise ValueError("the control token must follow predict_action of the same step")
        cache.pending = action.clone()  # (B, a), encoded with the tokens it goes with
        cache.awaiting_action, cache.step = False, cache.step + 1

    @_inference
    def feed_prefix(
        self, cache: StepCache, rtg: Tensor, ctg: Tensor, state: Tensor, action: Tensor
    ) -> None:
        """Feed the known steps ``0 .. k-1`` of a history into a fresh cache, in one pass.

        ``rtg``, ``ctg`` (B, k, 1), ``state`` (B, k, s) and ``action`` (B, k, a) are
        normalized, as in training (teacher forcing: the tokens ``[g] R C x u`` of every step
        with their time-step embeddings, :meth:`TokenCodec.embed_sequence`). Afterwards the
        cache stands at step ``k``: :meth:`predict_action` continues with step ``k``'s tokens,
        as if the ``k`` steps had been generated one call at a time (the same tokens, up to
        float rounding). ``k = 0`` feeds nothing.
        """
        if cache.step or cache.awaiting_action or cache.pending is not None:
            raise ValueError("feed_prefix starts a fresh cache (from start()), at step 0")
        if state.dim() != 3:
            raise ValueError(f"state must be (B, k, {self.codec.state_dim}), got {_shape(state)}")
        b, k = state.shape[:2]
        if b != cache.batch_size:
            raise ValueError(f"the prefix holds {b} sequences, the cache {cache.batch_size}")
        if k >= cache.max_steps:
            raise ValueError(f"a prefix of {k} steps leaves none of the cache's {cache.max_steps}")
        if k == 0:
            return
        batch = {"rtg": rtg, "ctg": ctg, "state": state, "action": action}
        if cache.target is not None:
            batch["target"] = cache.target
        self.codec.check_batch(batch)
        self._feed(cache, self.codec.embed_sequence(batch))
        cache.step = k


def eq8_loss(predictions: Mapping[str, Tensor], batch: Mapping[str, Tensor]) -> Tensor:
    """ART paper Eq. 8 with teacher forcing: squared error of the next states and controls.

    ``L = mean |x(t_{i+1}) - x_hat(t_{i+1})|^2 + mean |u(t_i) - u_hat(t_i)|^2``, each a mean
    over its elements (Eq. 8's sums, divided by their element counts so that the loss does
    not scale with the batch or the horizon). With ``batch["mask"]`` (B, T) only valid steps
    count: a control at a valid step, a next state when both steps are valid.
    """
    action_err = (predictions["action"] - batch["action"]) ** 2  # (B, T, a)
    state_err = (predictions["state"] - batch["state"][:, 1:]) ** 2  # (B, T-1, s)
    mask = batch.get("mask")
    if mask is None:
        return action_err.mean() + _mean_or_zero(state_err)
    pair = mask[:, 1:] & mask[:, :-1]  # (B, T-1)
    return _masked_mean(action_err, mask) + _masked_mean(state_err, pair)


def _masked_mean(err: Tensor, mask: Tensor) -> Tensor:
    weight = mask[..., None].to(err.dtype)  # (B, T, 1)
    count = weight.sum() * err.shape[-1]
    return (err * weight).sum() / count.clamp_min(1.0)


def _mean_or_zero(err: Tensor) -> Tensor:
    return err.mean() if err.numel() else err.sum()


def activation_fn(name: str):
    """The element-wise non-linearity named ``name`` (Table 4: ReLU)."""
    return {"relu": functional.relu, "gelu": functional.gelu}[name]


def init_weights(module: nn.Module, std: float = 0.02) -> None:
    """GPT-2 initialization: N(0, 0.02) weights, zero biases (nanoGPT's ``_init_weights``)."""
    if isinstance(module, nn.Linear):
        nn.init.normal_(module.weight, mean=0.0, std=std)
        if module.bias is not None:
            nn.init.zeros_(module.bias)
    elif isinstance(module, nn.Embedding):
        nn.init.normal_(module.weight, mean=0.0, std=std)


def residual_std(n_layer: int, std: float = 0.02) -> float:
    """GPT-2's scaled init of the projections into the residual stream."""
    return std / math.sqrt(2 * n_layer)


def _shape(value: Tensor) -> tuple[int, ...]:
    return tuple(value.shape)
