"""Reduced-precision convolutions emulated on the CPU: how NIDAR's outputs move under TF32 or bf16.

On Ampere and Hopper GPUs PyTorch computes float32 convolutions in TF32 by default
(``torch.backends.cudnn.allow_tf32``): the inputs and weights are rounded to a 10-bit mantissa
(float32's 8-bit exponent kept) and the products accumulated in float32. bfloat16 keeps 7 bits.
:func:`emulated_convolutions` reproduces that rounding with CPU arithmetic, so that the effect of
a GPU's precision on the model can be measured (``benchmarks/nidar_precision.py``) and tested
without a GPU.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch

__all__ = ["MANTISSA_BITS", "emulated_convolutions", "round_mantissa"]

#: Explicit mantissa bits of the formats a GPU may compute float32 convolutions in.
MANTISSA_BITS = {"float32": 23, "tf32": 10, "bf16": 7}


def round_mantissa(x: torch.Tensor, bits: int) -> torch.Tensor:
    """``x`` (float32) rounded to nearest with ``bits`` explicit mantissa bits (0 ≤ bits ≤ 23);
    the exponent range stays float32's. Ties round away from zero in magnitude."""
    if x.dtype != torch.float32:
        raise TypeError(f"round_mantissa needs float32, got {x.dtype}")
    if not 0 <= bits <= 23:
        raise ValueError(f"bits must be in [0, 23], got {bits}")
    if bits == 23:
        return x
    drop = 23 - bits
    raw = x.contiguous().view(torch.int32)
    return ((raw + (1 << (drop - 1))) & ~((1 << drop) - 1)).view(torch.float32)


@contextlib.contextmanager
def emulated_convolutions(fmt: str) -> Iterator[None]:
    """Within the block every float32 ``torch.nn.functional.conv2d`` (hence every
    :class:`torch.nn.Conv2d`) rounds its input and weight to ``fmt`` (a key of
    :data:`MANTISSA_BITS`) and accumulates in float32, as a GPU's tensor cores do. Other dtypes
    are untouched."""
    if fmt not in MANTISSA_BITS:
        raise ValueError(f"fmt must be one of {', '.join(MANTISSA_BITS)}, got {fmt!r}")
    bits = MANTISSA_BITS[fmt]
    conv2d = torch.nn.functional.conv2d

    def reduced(x, w, *args, **kwargs):
        if x.dtype == torch.float32:
            x, w = round_mantissa(x, bits), round_mantissa(w, bits)
        return conv2d(x, w, *args, **kwargs)

    torch.nn.functional.conv2d = reduced
    try:
        yield
    finally:
        torch.nn.functional.conv2d = conv2d
