"""Which low-precision generation kernels run on this machine.

ART generation can multiply by bfloat16 or int8 copies of its weights
(``model.start(..., bf16=True)`` / ``int8=True``, :mod:`scpformer.models.art`). Whether
those kernels run depends on the CPU, not only on the PyTorch build: oneDNN's bfloat16
product needs ``avx_ne_convert`` or ``avx512bw/vl/dq`` (an AVX2-only AMD EPYC has neither,
although ``torch.backends.mkldnn.is_available()`` is true there), and the int8 product needs
the x86 (fbgemm) quantized engine. So the answer is found by trying: the first call packs a
tiny linear layer in that format through the very functions generation uses, multiplies by
it, and catches what fails. The answer is cached for the process.

``SCPFORMER_DISABLE_BF16=1`` / ``SCPFORMER_DISABLE_INT8=1`` force the answer to False (read
at every call, so that a test or a user can see the unavailable path on any machine)::

    >>> low_precision_available("bf16") in (True, False)
    True
"""

from __future__ import annotations

import functools
import os

LOW_PRECISION = ("bf16", "int8")
DISABLE_VARIABLES = {"bf16": "SCPFORMER_DISABLE_BF16", "int8": "SCPFORMER_DISABLE_INT8"}
_FORMATS = {"bf16": "bfloat16", "int8": "int8"}  # name -> ART's weight layout


class LowPrecisionUnavailableError(ValueError):
    """bf16 or int8 generation was asked for on a machine whose kernels cannot run it."""


def low_precision_available(weights: str) -> bool:
    """Whether ``weights`` (``"bf16"`` or ``"int8"``) generation kernels run on this machine."""
    return unavailable_reason(weights) is None


def unavailable_reason(weights: str) -> str | None:
    """Why ``weights`` generation cannot run here, or None when it can (see the module)."""
    if weights not in LOW_PRECISION:
        raise ValueError(f"weights must be one of {LOW_PRECISION}, got {weights!r}")
    variable = DISABLE_VARIABLES[weights]
    if os.environ.get(variable, "").strip() not in ("", "0"):
        return f"disabled by {variable}={os.environ[variable]}"
    return _probe(weights)


def require_low_precision(weights: str) -> None:
    """Raise :class:`LowPrecisionUnavailableError` (one line) when ``weights`` cannot run."""
    reason = unavailable_reason(weights)
    if reason is not None:
        raise LowPrecisionUnavailableError(
            f"{weights} generation is not available on this machine ({reason}); "
            f"start() without {weights}=True runs in float32"
        )


@functools.cache
def _probe(weights: str) -> str | None:
    """Pack a 4x4 linear layer in ``weights`` and multiply by it; None, or what failed."""
    import torch

    from scpformer.models import art

    if weights == "bf16" and not art.onednn_available():
        return "PyTorch has no oneDNN (torch.backends.mkldnn) on this CPU"
    if weights == "int8":
        engines = torch.backends.quantized.supported_engines
        if "x86" not in engines and "fbgemm" not in engines:
            return "PyTorch has no x86 (fbgemm) quantized engine"
    generator = torch.Generator().manual_seed(0)
    weight = torch.randn(4, 4, generator=generator)
    bias = torch.randn(4, generator=generator)
    x = torch.randn(2, 4, generator=generator)
    layout = _FORMATS[weights]
    try:
        with torch.no_grad():
            pack = art._pack(weight, bias, layout, 1)
            if weights == "bf16":
                out = art.packed_linear_bf16(x, pack, bias.to(torch.bfloat16))
            else:
                out = art.quantized_linear(x, pack, None)
    except RuntimeError as err:
        return " ".join(str(err).split()) or type(err).__name__
    expected = torch.addmm(bias, x, weight.t())
    error = float((out - expected).norm() / expected.norm())
    if not error < 0.1:  # bf16: ~1e-3, int8: ~1e-2 on a 4x4 product
        return f"its product of a 4x4 test layer is off by {error:.2g} (relative)"
    return None


def single_thread_inference() -> None:
    """One torch thread for this process's batch-1 inference of a warm start.

    A batch-1 step is dozens of tiny products, where a second thread only adds
    synchronization: on the loaded 2-core development machine one ART rollout took 13-37 s
    with two threads and 0.1 s with one.
    """
    import torch

    torch.set_num_threads(1)
