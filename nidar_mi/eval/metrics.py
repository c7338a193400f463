"""Intensity metrics on projected maps and on point sets (NumPy in and out).

Intensities are compared on a common [0, 1] scale, as LiDAR4D does:
:func:`scale_intensity` divides by a stated scale and clips (the dataset's ``intensity_scale``).

**Maps** ((H, W): the LiDAR range image or the camera projection) with an optional validity
mask M:

* RMSE, MedAE: over the valid pixels.
* PSNR = 10 log10(1 / MSE) (peak 1; ``inf`` when the maps agree exactly on M).
* SSIM (Wang et al. 2004): 11x11 Gaussian window, σ = 1.5, K1 = 0.01, K2 = 0.03, data range 1,
  population (weighted) variances. The SSIM map is computed on the whole image with the invalid
  pixels of both maps set to 0, then averaged over the valid pixels. Within 5 px of the border
  the window is cut at the image edge and renormalised (the local statistics use only pixels
  inside the image), so the map has the input's size; farther in, it is the reference
  formulation exactly. It is the training loss's SSIM
  (:func:`nidar_mi.nidar.losses.ssim_map_torch`), evaluated in float64.
* LPIPS (AlexNet, via the ``lpips`` package): only with ImageNet AlexNet weights in the torch
  cache (``torch.hub.get_dir()/checkpoints/alexnet-owt-7be5be79.pth``); otherwise ``None`` with
  the reason, never a random backbone. The backbone is loaded from that file with
  ``weights_only=True``. The grey map is replicated to three channels. With every pixel valid
  this is the standard LPIPS (each layer's distance map averaged at its own resolution); with a
  mask, invalid pixels are set to 0 and the spatial LPIPS map (layer maps upsampled to the
  input size) is averaged over the valid pixels. AlexNet needs maps of at least 31 x 31 pixels.

**Points** ((N,) arrays): RMSE, MAE and Spearman's rank correlation, the package's one
(:func:`spearman`): average ranks for ties; ``nan`` when either side is constant or there are
fewer than 3 pairs (two points always rank ±1: no evidence of an order); an error for
non-finite values or shapes that differ.
"""

from __future__ import annotations

import functools
import os
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = [
    "ALEXNET_CHECKPOINT",
    "LPIPS_MIN_SIDE",
    "alexnet_checkpoint_path",
    "lpips_alex",
    "lpips_unavailable_reason",
    "mae",
    "map_metrics",
    "medae",
    "point_metrics",
    "psnr",
    "rmse",
    "scale_intensity",
    "SPEARMAN_MIN_PAIRS",
    "spearman",
    "ssim",
    "ssim_map",
]

ALEXNET_CHECKPOINT = "alexnet-owt-7be5be79.pth"
"""File name of torchvision's ImageNet AlexNet weights in the torch hub cache."""
LPIPS_MIN_SIDE = 31
"""Smallest map side AlexNet's first five layers accept."""


def scale_intensity(x: Any, scale: float) -> np.ndarray:
    """Intensity on the [0, 1] metric scale: ``clip(x / scale, 0, 1)``.

    Args:
        x: intensities, any shape.
        scale: positive finite divisor (the dataset's ``intensity_scale``).

    Returns:
        float64 array of ``x``'s shape (NaN stays NaN).
    """
    scale = float(scale)
    if not np.isfinite(scale) or scale <= 0.0:
        raise NidarError(f"intensity scale must be a positive finite number (got {scale})")
    return np.clip(np.asarray(x, dtype=np.float64) / scale, 0.0, 1.0)


def _pair(pred: Any, gt: Any, mask: Any = None, *, ndim: int | None = None):
    """Checked float64 ``pred``, ``gt`` and a bool mask of their shape with a valid pixel."""
    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    if p.shape != g.shape:
        raise NidarError(f"pred and gt shapes differ: {p.shape} vs {g.shape}")
    if ndim is not None and p.ndim != ndim:
        raise NidarError(f"expected {ndim}-D arrays, got shape {p.shape}")
    if mask is None:
        m = np.ones(p.shape, dtype=bool)
    else:
        m = np.asarray(mask)
        if m.shape != p.shape:
            raise NidarError(f"mask shape {m.shape} differs from the maps' {p.shape}")
        m = m.astype(bool)
    if not m.any():
        raise NidarError("no valid pixels or points to compare")
    for name, a in (("pred", p), ("gt", g)):
        if not np.all(np.isfinite(a[m])):
            raise NidarError(f"{name} has non-finite values where valid")
    return p, g, m


def rmse(pred: Any, gt: Any, mask: Any = None) -> float:
    """Root-mean-square error over the valid entries (any matching shapes)."""
    p, g, m = _pair(pred, gt, mask)
    return float(np.sqrt(np.mean((p[m] - g[m]) ** 2)))


def mae(pred: Any, gt: Any, mask: Any = None) -> float:
    """Mean absolute error over the valid entries."""
    p, g, m = _pair(pred, gt, mask)
    return float(np.mean(np.abs(p[m] - g[m])))


def medae(pred: Any, gt: Any, mask: Any = None) -> float:
    """Median absolute error over the valid entries."""
    p, g, m = _pair(pred, gt, mask)
    return float(np.median(np.abs(p[m] - g[m])))


def psnr(pred: Any, gt: Any, mask: Any = None) -> float:
    """Peak signal-to-noise ratio with peak 1, ``10 log10(1 / MSE)`` in dB (``inf`` if MSE = 0)."""
    p, g, m = _pair(pred, gt, mask)
    mse = float(np.mean((p[m] - g[m]) ** 2))
    return float("inf") if mse == 0.0 else float(10.0 * np.log10(1.0 / mse))


# --- SSIM ------------------------------------------------------------------------------------


def ssim_map(x: Any, y: Any) -> np.ndarray:
    """Per-pixel SSIM of two (H, W) maps in [0, 1] (data range 1), in float64.

    This evaluates the package's one SSIM, :func:`nidar_mi.nidar.losses.ssim_map_torch` (the one the
    training loss uses): 11x11 Gaussian window (σ = 1.5), cut at the image edge and
    renormalised; variances and covariance are the window-weighted population ones.

    Args:
        x: (H, W) map.
        y: (H, W) map.

    Returns:
        (H, W) float64 SSIM values in [-1, 1].
    """
    import torch

    from ..nidar.losses import ssim_map_torch

    x, y, _ = _pair(x, y, ndim=2)
    with torch.no_grad():
        s = ssim_map_torch(torch.from_numpy(x)[None, None], torch.from_numpy(y)[None, None])
    return s[0, 0].numpy()


def ssim(pred: Any, gt: Any, mask: Any = None) -> float:
    """Mean SSIM over the valid pixels, invalid pixels of both maps set to 0 first.

    Args:
        pred: (H, W) map in [0, 1].
        gt: (H, W) map in [0, 1].
        mask: optional (H, W) bool validity; values outside it may be non-finite.
    """
    p, g, m = _pair(pred, gt, mask, ndim=2)
    s = ssim_map(np.where(m, p, 0.0), np.where(m, g, 0.0))
    return float(np.mean(s[m]))


# --- rank correlation -------------------------------------------------------------------------


#: Fewest pairs :func:`spearman` scores (with two, ρ is ±1 whatever the values).
SPEARMAN_MIN_PAIRS = 3


def spearman(pred: Any, gt: Any) -> float:
    """Spearman's rank correlation (:func:`scipy.stats.spearmanr`; average ranks for ties).

    Args:
        pred: (N,) finite values.
        gt: (N,) finite values.

    Returns:
        ρ in [-1, 1]; ``nan`` when either input is constant or N < :data:`SPEARMAN_MIN_PAIRS`
        (empty included).

    Raises:
        NidarError: the shapes differ or are not 1-D, or a value is not finite.
    """
    from scipy.stats import spearmanr

    p = np.asarray(pred, dtype=np.float64)
    g = np.asarray(gt, dtype=np.float64)
    if p.size == 0 and g.size == 0 and p.ndim == g.ndim == 1:
        return float("nan")
    p, g, _ = _pair(p, g, ndim=1)
    if p.size < SPEARMAN_MIN_PAIRS or np.all(p == p[0]) or np.all(g == g[0]):
        return float("nan")
    return float(np.clip(spearmanr(p, g).statistic, -1.0, 1.0))


# --- LPIPS -------------------------------------------------------------------------------------


def alexnet_checkpoint_path() -> str:
    """Where torchvision keeps its ImageNet AlexNet weights: ``<torch hub dir>/checkpoints/``."""
    import torch

    return os.path.join(torch.hub.get_dir(), "checkpoints", ALEXNET_CHECKPOINT)


def lpips_unavailable_reason() -> str | None:
    """Why LPIPS cannot be computed here, or ``None`` when it can.

    LPIPS needs the ``lpips`` package (which imports torchvision) and torchvision's ImageNet
    AlexNet weights already in the torch cache (nothing is downloaded).
    """
    try:
        import lpips  # noqa: F401
    except Exception as e:  # a broken torchvision raises more than ImportError
        return f"the lpips package does not import ({type(e).__name__}: {e})"
    path = alexnet_checkpoint_path()
    if not os.path.isfile(path):
        return f"no ImageNet AlexNet weights at {path}"
    return None


@functools.cache
def _lpips_model(path: str):
    """LPIPS (AlexNet, v0.1) with its backbone loaded from ``path``."""
    import lpips
    import torch

    model = lpips.LPIPS(net="alex", pretrained=True, pnet_rand=True, spatial=False, verbose=False)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated file, or something other than plain tensors
        raise NidarError(f"{path}: not readable as weights ({type(e).__name__})") from None
    if not isinstance(state, dict):
        raise NidarError(f"{path}: not a state dict")
    loaded = {}
    for name, param in model.net.named_parameters():
        _slice, index, kind = name.split(".")  # "slice2.3.weight" holds features[3].weight
        key = f"features.{index}.{kind}"
        if key not in state or tuple(state[key].shape) != tuple(param.shape):
            raise NidarError(f"{path}: no AlexNet parameter {key} of shape {tuple(param.shape)}")
        loaded[name] = state[key]
    model.net.load_state_dict(loaded, strict=True)
    return model.eval()


def lpips_alex(pred: Any, gt: Any, mask: Any = None) -> tuple[float | None, str | None]:
    """LPIPS (AlexNet) between two (H, W) maps in [0, 1], averaged over the valid pixels.

    Args:
        pred: (H, W) map in [0, 1].
        gt: (H, W) map in [0, 1].
        mask: optional (H, W) bool validity; invalid pixels of both maps are set to 0.

    Returns:
        ``(value, None)``, or ``(None, reason)`` when LPIPS is unavailable (see
        :func:`lpips_unavailable_reason`) or the map is smaller than 31 x 31.
    """
    p, g, m = _pair(pred, gt, mask, ndim=2)
    if min(p.shape) < LPIPS_MIN_SIDE:
        return None, f"map {p.shape} is smaller than AlexNet's {LPIPS_MIN_SIDE} x {LPIPS_MIN_SIDE}"
    reason = lpips_unavailable_reason()
    if reason is not None:
        return None, reason
    import torch

    try:
        model = _lpips_model(alexnet_checkpoint_path())
    except NidarError as e:
        return None, str(e)
    t = [
        torch.from_numpy(np.where(m, a, 0.0).astype(np.float32))[None, None].expand(1, 3, -1, -1)
        for a in (p, g)
    ]
    full = bool(m.all())
    model.spatial = not full  # full map: the standard LPIPS; else its spatial map on M
    with torch.no_grad():
        d = model(t[0], t[1], normalize=True)  # [0, 1] -> [-1, 1] inside
    if full:
        return float(d.reshape(-1)[0]), None
    d = d.reshape(p.shape).double().numpy()
    return float(np.mean(d[m])), None


# --- bundles ------------------------------------------------------------------------------------


def map_metrics(
    pred: Any, gt: Any, mask: Any = None, *, scale: float | None = None, lpips: bool = True
) -> dict[str, Any]:
    """Every map metric for one pair of projected intensity maps.

    Args:
        pred: (H, W) predicted intensity.
        gt: (H, W) reference intensity.
        mask: optional (H, W) bool validity (e.g. the dataset's ``mask``).
        scale: when given, both maps go through :func:`scale_intensity` first; otherwise they
            must already be on the [0, 1] scale.
        lpips: compute LPIPS (else reported as not requested).

    Returns:
        ``{"n": valid pixels, "rmse", "medae", "psnr" (dB), "ssim", "lpips": float or None,
        "lpips_reason": None or why LPIPS is missing}``.
    """
    p, g, m = _pair(pred, gt, mask, ndim=2)
    if scale is not None:
        p, g = scale_intensity(p, scale), scale_intensity(g, scale)
    if lpips:
        value, reason = lpips_alex(p, g, m)
    else:
        value, reason = None, "not requested"
    return {
        "n": int(m.sum()),
        "rmse": rmse(p, g, m),
        "medae": medae(p, g, m),
        "psnr": psnr(p, g, m),
        "ssim": ssim(p, g, m),
        "lpips": value,
        "lpips_reason": reason,
    }


def point_metrics(pred: Any, gt: Any, *, scale: float | None = None) -> dict[str, Any]:
    """Point-wise metrics for intensities at the same N points.

    Args:
        pred: (N,) predicted intensity.
        gt: (N,) reference intensity.
        scale: when given, both go through :func:`scale_intensity` first.

    Returns:
        ``{"n", "rmse", "mae", "spearman"}``.
    """
    p, g, _ = _pair(pred, gt, ndim=1)
    if scale is not None:
        p, g = scale_intensity(p, scale), scale_intensity(g, scale)
    return {"n": int(p.size), "rmse": rmse(p, g), "mae": mae(p, g), "spearman": spearman(p, g)}
