"""A small learned head: a two-layer perceptron on a return's inputs, the fast ``context`` model.

The ``context`` profile form (:mod:`nidar_mi.profiles.context`) can hold a LightGBM regression
or this head in its place: ``F(x) = W3 · relu(W2 · relu(W1 · z + b1) + b2) + b3`` with ``z``
the inputs standardised by the training rows' mean and standard deviation (a missing input,
NaN, at its mean: 0; each ``z`` clipped to ±:data:`CLIP`), :data:`HIDDEN` units per layer.
Evaluating it is two small matrix products per return in NumPy (float32), some thirty times
cheaper than 400 trees of 63 leaves (docs/BENCHMARKS.md); on drives it was not fitted on it
ranks the intensities far below the trees, about as the range, elevation and incidence alone
do (docs/NIDAR.md, "What the fast paths cost").

Fitting (:func:`fit_head`, settings fixed beforehand, not tuned on held-out data): least
squares, Adam (learning rate :data:`LEARNING_RATE`, weight decay :data:`WEIGHT_DECAY`),
:data:`STEPS` steps on seeded mini-batches of :data:`BATCH` rows (passes over the rows, each a
new permutation), in torch on the CPU; the same rows, seed and thread count give the same head. The head is stored as JSON
numbers (:func:`head_to_dict`), checked on reading (:func:`head_from_dict`); nothing pickled.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = [
    "BATCH",
    "CLIP",
    "STEPS",
    "HIDDEN",
    "LEARNING_RATE",
    "WEIGHT_DECAY",
    "fit_head",
    "head_from_dict",
    "head_predict",
    "head_to_dict",
]

#: Units of each hidden layer.
HIDDEN = 64
#: Optimiser steps (the rows drawn in seeded passes, each pass a new permutation): the same
#: work for a frame or a hundred.
STEPS = 2000
#: Rows per step.
BATCH = 2048
#: Adam's learning rate.
LEARNING_RATE = 2e-3
#: Adam's (decoupled) weight decay.
WEIGHT_DECAY = 1e-4
#: Bound of a standardised input.
CLIP = 10.0
#: Largest number of hidden units or inputs a stored head may have.
MAX_UNITS = 1024


def _standardise(x: np.ndarray, mean: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """(N, F) float32 ``clip((x - mean) / scale, ±CLIP)``, NaN at 0 (in place on one copy)."""
    z = np.array(x, dtype=np.float32)
    z -= mean.astype(np.float32)
    z *= (1.0 / scale).astype(np.float32)
    np.nan_to_num(z, copy=False, nan=0.0)
    return np.clip(z, -CLIP, CLIP, out=z)


def fit_head(x: np.ndarray, y: np.ndarray, *, seed: int = 0, threads: int = 1, weight=None) -> dict:
    """Fit the head on (N, F) inputs (NaN: missing) and (N,) targets (module docstring), the
    squared errors weighted by ``weight`` (N,) when given.

    Returns:
        ``{"mean", "scale", "layers"}``: (F,) float64 standardisation and the three layers as
        ``(weight (out, in), bias (out,))`` float32 arrays.
    """
    import torch

    x = np.asarray(x, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        mean = np.nan_to_num(np.nanmean(x, axis=0)) if len(x) else np.zeros(x.shape[1])
        sd = np.nan_to_num(np.nanstd(x, axis=0))
    scale = np.where(sd > 1e-12, sd, 1.0)
    z = torch.from_numpy(_standardise(x, mean, scale))
    t = torch.from_numpy(np.asarray(y, dtype=np.float32).reshape(-1, 1))
    w = None if weight is None else torch.from_numpy(np.asarray(weight, np.float32).reshape(-1, 1))
    previous = torch.get_num_threads()
    torch.set_num_threads(int(threads))
    try:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(int(seed))
            net = torch.nn.Sequential(
                torch.nn.Linear(z.shape[1], HIDDEN),
                torch.nn.ReLU(),
                torch.nn.Linear(HIDDEN, HIDDEN),
                torch.nn.ReLU(),
                torch.nn.Linear(HIDDEN, 1),
            )
            opt = torch.optim.AdamW(net.parameters(), lr=LEARNING_RATE, weight_decay=WEIGHT_DECAY)
            gen = torch.Generator().manual_seed(int(seed))
            steps = 0
            while steps < STEPS:
                for batch in torch.randperm(len(z), generator=gen).split(BATCH)[: STEPS - steps]:
                    opt.zero_grad()
                    err = torch.square(net(z[batch]) - t[batch])
                    loss = err.mean() if w is None else (err * w[batch]).sum() / w[batch].sum()
                    loss.backward()
                    opt.step()
                    steps += 1
    finally:
        torch.set_num_threads(previous)
    linear = [m for m in net if isinstance(m, torch.nn.Linear)]
    layers = [(m.weight.detach().numpy().copy(), m.bias.detach().numpy().copy()) for m in linear]
    return {"mean": mean, "scale": scale, "layers": layers}


def head_predict(head: Mapping[str, Any], x: np.ndarray) -> np.ndarray:
    """(N,) float64 outputs of a head for (N, F) inputs (NaN: missing)."""
    h = _standardise(np.asarray(x, dtype=np.float64), head["mean"], head["scale"])
    layers = head["layers"]
    for i, (w, b) in enumerate(layers):
        h = h @ w.T + b
        if i < len(layers) - 1:
            np.maximum(h, 0.0, out=h)
    return h[:, 0].astype(np.float64)


def head_to_dict(head: Mapping[str, Any]) -> dict[str, Any]:
    """JSON numbers of a head: the standardisation, and each layer's weight rows and bias."""
    return {
        "mean": [float(v) for v in head["mean"]],
        "scale": [float(v) for v in head["scale"]],
        "layers": [
            {
                "weight": np.asarray(w, np.float64).tolist(),
                "bias": np.asarray(b, np.float64).tolist(),
            }
            for w, b in head["layers"]
        ],
    }


def head_from_dict(data: Any, n_inputs: int) -> dict:
    """Inverse of :func:`head_to_dict` for a head of ``n_inputs`` inputs.

    Raises:
        NidarError: not a head of that many inputs (shapes that do not chain, one output,
            non-finite or non-positive scales, non-finite weights, too many units).
    """
    if not isinstance(data, Mapping) or set(data) != {"mean", "scale", "layers"}:
        raise NidarError("head: expected 'mean', 'scale' and 'layers'")
    try:
        mean = np.asarray(data["mean"], dtype=np.float64)
        scale = np.asarray(data["scale"], dtype=np.float64)
        layers = []
        for layer in data["layers"]:
            if not isinstance(layer, Mapping) or set(layer) != {"weight", "bias"}:
                raise NidarError("head: each layer has a 'weight' and a 'bias'")
            w = np.asarray(layer["weight"], dtype=np.float32)
            b = np.asarray(layer["bias"], dtype=np.float32)
            layers.append((w, b))
    except (TypeError, ValueError):
        raise NidarError("head: numbers expected") from None
    if mean.shape != (n_inputs,) or scale.shape != (n_inputs,) or not np.all(scale > 0):
        raise NidarError(f"head: 'mean' and positive 'scale' of {n_inputs} inputs expected")
    width = n_inputs
    for w, b in layers:
        if w.ndim != 2 or w.shape[1] != width or b.shape != (w.shape[0],) or w.shape[0] > MAX_UNITS:
            raise NidarError("head: the layers' shapes do not chain")
        width = w.shape[0]
    if not layers or width != 1:
        raise NidarError("head: the last layer must give one output")
    finite = [mean, scale, *(a for wb in layers for a in wb)]
    if not all(np.all(np.isfinite(a)) for a in finite):
        raise NidarError("head: non-finite numbers")
    return {"mean": mean, "scale": scale, "layers": layers}
