"""Networks prepared for inference: BatchNorm folded into the convolutions, channels-last memory.

In eval mode a BatchNorm layer is an affine map per channel, ``y = γ (x − μ) / sqrt(σ² + ε) + β``;
when its input is the output of a convolution and nothing else reads that output, the map can be
folded into the convolution's weights and bias::

    W' = W · s,   b' = (b − μ) · s + β,   s = γ / sqrt(σ² + ε)   (per output channel)

and the BatchNorm layer replaced by the identity. :func:`fold_batchnorm` finds the pairs by
running the network once with hooks (so every architecture of :mod:`nidar_mi.nidar` is covered
without a list of its layers), folds them in a copy, and checks that the folded copy gives the
same outputs as the original on that input (|Δ| ≤ 1e-5 · max(1, |y|) in float32). Folding removes a
memory pass per layer; channels-last memory (:func:`prepare_for_inference`) lets oneDNN pick
its fastest convolution kernels on CPUs.
"""

from __future__ import annotations

import copy

import torch
from torch import nn

from ..errors import NidarError

__all__ = [
    "FOLD_TOLERANCE",
    "fold_batchnorm",
    "fold_conv_bn",
    "fold_error",
    "prepare_for_inference",
]

#: Largest change of any output, relative to max(1, |output|), that folding may cause.
FOLD_TOLERANCE = 1e-5


def fold_conv_bn(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> nn.Conv2d:
    """A convolution equal to ``bn(conv(x))`` for a BatchNorm in eval mode.

    Args:
        conv: a 2-D convolution (any stride, dilation, groups; bias or not).
        bn: the BatchNorm that reads its output, with running statistics.

    Returns:
        A new :class:`torch.nn.Conv2d` with a bias (the inputs are not changed).
    """
    if bn.running_mean is None or bn.running_var is None:
        raise NidarError("fold_conv_bn: the BatchNorm has no running statistics")
    fused = copy.deepcopy(conv)
    with torch.no_grad():
        scale = bn.weight / torch.sqrt(bn.running_var + bn.eps) if bn.affine else None
        if scale is None:
            scale = 1.0 / torch.sqrt(bn.running_var + bn.eps)
        shift = bn.bias if bn.affine else torch.zeros_like(bn.running_mean)
        w = conv.weight * scale.reshape(-1, 1, 1, 1)
        b = conv.bias if conv.bias is not None else torch.zeros_like(bn.running_mean)
        fused.weight = nn.Parameter(w)
        fused.bias = nn.Parameter((b - bn.running_mean) * scale + shift)
    return fused


def _trace_pairs(net: nn.Module, example: torch.Tensor) -> list[tuple[str, str]]:
    """``(conv name, bn name)`` pairs where the BatchNorm reads exactly the convolution's output
    tensor and no other module reads it (found by running ``net`` once with hooks)."""
    produced: dict[int, str] = {}
    readers: dict[int, list[str]] = {}
    keep: list[torch.Tensor] = []  # hold tensors so that their ids are not reused
    hooks = []

    def on_output(name):
        def hook(module, inputs, output):
            if isinstance(output, torch.Tensor):
                produced[id(output)] = name
                keep.append(output)

        return hook

    def on_input(name):
        def hook(module, inputs):
            for t in inputs:
                if isinstance(t, torch.Tensor):
                    readers.setdefault(id(t), []).append(name)
                    keep.append(t)

        return hook

    modules = dict(net.named_modules())
    for name, m in modules.items():
        if isinstance(m, nn.Conv2d):
            hooks.append(m.register_forward_hook(on_output(name)))
        if not list(m.children()):  # every leaf module that reads a tensor
            hooks.append(m.register_forward_pre_hook(on_input(name)))
    try:
        with torch.no_grad():
            net(example)
    finally:
        for h in hooks:
            h.remove()
    pairs = []
    for tid, conv_name in produced.items():
        who = readers.get(tid, [])
        if len(who) == 1 and isinstance(modules[who[0]], nn.BatchNorm2d):
            pairs.append((conv_name, who[0]))
    return pairs


def _set(net: nn.Module, name: str, module: nn.Module) -> None:
    parent, _, leaf = name.rpartition(".")
    setattr(net.get_submodule(parent) if parent else net, leaf, module)


def _flat(out) -> list[torch.Tensor]:
    if isinstance(out, torch.Tensor):
        return [out]
    if isinstance(out, dict):
        return [out[k] for k in sorted(out)]
    return list(out)


def fold_batchnorm(net: nn.Module, example: torch.Tensor) -> nn.Module:
    """A copy of ``net`` (in eval mode) with every foldable BatchNorm folded into its convolution.

    Args:
        net: a network; its BatchNorm layers must have running statistics.
        example: a valid input ``(B, C, H, W)`` for ``net`` (used to find the pairs and to check
            the result; a small one suffices).

    Returns:
        The folded copy, in eval mode; ``net`` is not changed. A convolution whose output is also
        read elsewhere (or a BatchNorm that reads anything else) is left as it is.

    Raises:
        NidarError: the folded copy differs from ``net`` on ``example`` by more than
            :data:`FOLD_TOLERANCE` (relative to max(1, |output|)) in float64
            (:func:`fold_error`).
    """
    folded = copy.deepcopy(net).eval()
    modules = dict(folded.named_modules())
    for conv_name, bn_name in _trace_pairs(folded, example):
        _set(folded, conv_name, fold_conv_bn(modules[conv_name], modules[bn_name]))
        _set(folded, bn_name, nn.Identity())
    err = fold_error(net, folded, example)
    if not err <= FOLD_TOLERANCE:
        raise NidarError(f"fold_batchnorm: folding changed an output by {err:.2e}")
    return folded


def fold_error(net: nn.Module, folded: nn.Module, example: torch.Tensor) -> float:
    """Largest change of any output of ``folded`` against ``net`` on ``example``, relative to
    max(1, |output|), computed on float64 CPU copies of both networks (so the number measures the
    fold, not the reduced precision, e.g. TF32, that a GPU backend computes float32 in)."""
    ref64 = copy.deepcopy(net).eval().to("cpu", torch.float64)
    fold64 = copy.deepcopy(folded).eval().to("cpu", torch.float64)
    x = example.detach().to("cpu", torch.float64)
    err = 0.0
    with torch.no_grad():
        for a, b in zip(_flat(ref64(x)), _flat(fold64(x)), strict=True):
            err = max(err, ((a - b).abs() / a.abs().clamp(min=1.0)).max().item())
    return err


def prepare_for_inference(
    net: nn.Module, example: torch.Tensor, *, fold: bool = True, channels_last: bool = True
) -> nn.Module:
    """``net`` ready for fast inference: BatchNorm folded (a copy) and channels-last memory.

    Args:
        net: a network in any mode.
        example: a valid input for ``net`` (see :func:`fold_batchnorm`).
        fold: fold BatchNorm into the convolutions.
        channels_last: convert the parameters to ``torch.channels_last`` (inputs are converted by
            :func:`nidar_mi.nidar.infer.predict`).

    Returns:
        A network in eval mode (``net`` itself when neither option is set, else a copy).
    """
    out = fold_batchnorm(net, example) if fold else net.eval()
    if channels_last:
        out = out.to(memory_format=torch.channels_last)
    return out
