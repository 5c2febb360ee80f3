"""Low-precision capability: tried once on this CPU, forced off by an environment variable."""

import pytest

torch = pytest.importorskip("torch")

from scpformer.models import capabilities  # noqa: E402
from scpformer.models.capabilities import (  # noqa: E402
    LowPrecisionUnavailableError,
    low_precision_available,
    require_low_precision,
    unavailable_reason,
)


@pytest.mark.parametrize("weights", ["bf16", "int8"])
def test_available_kernels_generate_and_unavailable_ones_fail_as_the_reason_says(weights):
    from scpformer.models.art import ART, ArtConfig, _pack

    model = ART(ArtConfig(n_layer=1, n_head=2, n_embd=16, context=4, dropout=0.0)).eval()
    reason = unavailable_reason(weights)
    if reason is None:
        cache = model.start(9, **{weights: True})  # batch 9: the oneDNN layout
        action = model.predict_action(cache, torch.ones(9, 1), torch.ones(9, 1), torch.ones(9, 6))
        assert action.shape == (9, 3) and torch.isfinite(action).all()
        return
    assert reason and "\n" not in reason
    with pytest.raises(LowPrecisionUnavailableError, match=weights):
        model.start(9, **{weights: True})
    if not reason.startswith(("disabled by", "PyTorch has no", "its product")):
        with pytest.raises(RuntimeError):  # the kernel's own failure, which the reason quotes
            _pack(torch.eye(4), torch.zeros(4), {"bf16": "bfloat16"}.get(weights, weights), 1)


@pytest.mark.parametrize("weights", ["bf16", "int8"])
def test_the_environment_variable_forces_the_capability_off(monkeypatch, weights):
    variable = f"SCPFORMER_DISABLE_{weights.upper()}"
    monkeypatch.setenv(variable, "1")
    assert not low_precision_available(weights)
    with pytest.raises(LowPrecisionUnavailableError, match=f"disabled by {variable}=1"):
        require_low_precision(weights)
    monkeypatch.setenv(variable, "0")
    assert low_precision_available(weights) is (capabilities._probe(weights) is None)


def test_unknown_formats_are_an_error():
    with pytest.raises(ValueError, match="weights must be one of"):
        low_precision_available("fp8")
