"""GRU and LSTM baselines of the ART paper (Tables 2-3), behind ART's interface.

Same token sequence, encoders, time-step embedding and decoders as ART
(:mod:`scpformer.models.sequence`); a recurrent core (``torch.nn.GRU`` or ``torch.nn.LSTM``)
replaces the transformer blocks. Trained by the same loop on the same Eq. 8 loss; in
generation the "cache" is the recurrent hidden state, so each call also feeds only the new
tokens.

The papers give no sizes for their recurrent baselines; the presets use ART's embedding
width (``paper``: 384, ``small``: 128) with 2 recurrent layers.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from torch import Tensor, nn

from scpformer.models.sequence import (
    StepCache,
    TokenSequenceModel,
    check_sizes,
    init_weights,
)

CELLS = ("gru", "lstm")


@dataclass(frozen=True, kw_only=True)
class RnnConfig:
    """Sizes of a recurrent baseline."""

    cell: str = "gru"  # recurrent cell: gru or lstm
    n_layer: int = 2  # stacked recurrent layers
    n_embd: int = 384  # token embedding and hidden state width
    context: int = 100  # largest number of time steps
    dropout: float = 0.1  # dropout on the embeddings and between layers (training only)
    state_dim: int = 6  # x: RTN [m, m/s] or ROE [m]
    action_dim: int = 3  # u: impulse dv in RTN [m/s]
    target_dim: int = 0  # g: target state token (6 for robust ART's five modalities)

    def __post_init__(self) -> None:
        if self.cell not in CELLS:
            raise ValueError(f"cell must be one of {CELLS}, got {self.cell!r}")
        check_sizes(self)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (``RnnConfig(**config.to_dict())`` rebuilds it)."""
        return dataclasses.asdict(self)


RNN_PRESETS: dict[str, RnnConfig] = {
    "paper": RnnConfig(n_layer=2, n_embd=384),
    "small": RnnConfig(n_layer=2, n_embd=128),
}


@dataclass(eq=False, kw_only=True)
class RnnCache(StepCache):
    """The recurrent state after the tokens fed so far (None before the first call)."""

    hidden: Tensor | tuple[Tensor, Tensor] | None = None  # (layers, B, C) [and cell state]


class SequenceRNN(TokenSequenceModel):
    """A GRU or LSTM over ART's token sequence (see the module docstring)."""

    def __init__(self, config: RnnConfig) -> None:
        super().__init__(config, RnnConfig)
        core = nn.GRU if config.cell == "gru" else nn.LSTM
        self.core = core(
            config.n_embd,
            config.n_embd,
            num_layers=config.n_layer,
            batch_first=True,
            dropout=config.dropout if config.n_layer > 1 else 0.0,
        )
        self.codec.apply(init_weights)

    def _core(self, tokens: Tensor) -> Tensor:  # (B, L, C)
        return self.core(tokens)[0]  # (B, L, C)

    def _empty_cache(
        self, batch_size: int, max_steps: int, target: Tensor | None, weights: str
    ) -> RnnCache:
        if weights != "float32":
            raise ValueError(f"{weights} generation is implemented for ART only")
        return RnnCache(batch_size=batch_size, max_steps=max_steps, target=target)

    def _feed(self, cache: RnnCache, tokens: Tensor) -> Tensor:  # tokens (B, n, C)
        out, cache.hidden = self.core(tokens, cache.hidden)  # (B, n, C)
        return out[:, -1]  # (B, C)
