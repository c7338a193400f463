"""Image preparation shared by training and inference.

Camera frames arrive as 8-bit sRGB; the NIR target is linear band radiance. Both are brought
to a common, exposure-free scale before they reach a network:

1. sRGB is decoded to linear RGB with the IEC 61966-2-1 transfer function
   (:func:`nidar_mi.io.images.srgb_to_linear`), so that the
   spectral translation network combines linear radiances, as the cross-spectral image model
   ``NIR ~ sum_c w_c * RGB_c`` assumes.
2. Each image is multiplied by ``target_mean / (mean + eps)`` and clipped to
   ``[0, clamp_max]``: the per-image exposure normalisation of cs-stereo (Zhi et al., CVPR
   2018), which maps an unknown camera exposure to a mean of 0.5. The absolute scale of the
   NIR band is not recoverable from an 8-bit sRGB image, so the networks work in this
   normalised domain.
"""

from __future__ import annotations

import numpy as np

from ..errors import NidarError
from ..io.images import srgb_to_linear

__all__ = [
    "EXPOSURE_TARGET_MEAN",
    "EXPOSURE_CLAMP_MAX",
    "normalize_exposure",
    "prepare_rgb",
    "prepare_nir",
    "chromaticity",
    "colour_input",
]

#: Mean value an image has after exposure normalisation.
EXPOSURE_TARGET_MEAN = 0.5
#: Upper clip after exposure normalisation (cs-stereo's ``clamp_value``).
EXPOSURE_CLAMP_MAX = 5.0
_EPS = 1e-3


def normalize_exposure(
    image: np.ndarray,
    target_mean: float = EXPOSURE_TARGET_MEAN,
    clamp_max: float = EXPOSURE_CLAMP_MAX,
) -> np.ndarray:
    """Scale an image to mean ``target_mean`` and clip it to ``[0, clamp_max]``.

    Args:
        image: float array of any shape (linear radiance, arbitrary unit).
        target_mean: mean after scaling (before clipping).
        clamp_max: upper clip.

    Returns:
        float32 array of the same shape: ``clip(image * target_mean / (mean + 1e-3), 0,
        clamp_max)``.
    """
    image = np.asarray(image, dtype=np.float32)
    if not np.all(np.isfinite(image)):
        raise NidarError("image to normalise contains NaN or infinite values")
    ratio = np.float32(target_mean) / (np.float32(image.mean(dtype=np.float64)) + np.float32(_EPS))
    return np.clip(image * ratio, 0.0, clamp_max).astype(np.float32)


def prepare_rgb(rgb: np.ndarray) -> np.ndarray:
    """Network input from a camera image: linear, exposure-normalised, channels first.

    Args:
        rgb: ``(H, W, 3)`` uint8 sRGB image.

    Returns:
        ``(3, H, W)`` float32 linear RGB with mean ~0.5, in ``[0, 5]``.
    """
    _check_rgb(rgb)
    linear = srgb_to_linear(rgb.astype(np.float32) / np.float32(255.0))
    return np.ascontiguousarray(normalize_exposure(linear).transpose(2, 0, 1))


def prepare_nir(nir: np.ndarray) -> np.ndarray:
    """Spectral-translation target from NIR band radiance.

    Args:
        nir: ``(H, W)`` float linear NIR radiance (any unit).

    Returns:
        ``(1, H, W)`` float32, exposure-normalised (mean ~0.5, in ``[0, 5]``).
    """
    nir = np.asarray(nir)
    if nir.ndim != 2:
        raise NidarError(f"NIR image must be (H, W), got shape {nir.shape}")
    return normalize_exposure(nir)[None]


#: Added to the channel sum of :func:`chromaticity` (prepared RGB has mean 0.5 per channel).
CHROMA_EPS = 1e-2


def chromaticity(x: np.ndarray) -> np.ndarray:
    """Shading-free colour of prepared RGB: ``x / (sum of channels + CHROMA_EPS)``.

    Args:
        x: ``(3, H, W)`` prepared RGB (:func:`prepare_rgb`).

    Returns:
        ``(3, H, W)`` float32 in ``[0, 1]``: each pixel's share of red, green and blue, the
        same under any brightness of its light (a black pixel gives 0).
    """
    return (x / (x.sum(0, keepdims=True) + np.float32(CHROMA_EPS))).astype(np.float32)


def colour_input(rgb: np.ndarray, mode: str) -> np.ndarray:
    """The colour channels IRNet receives before its pseudo-NIR channel.

    Args:
        rgb: ``(H, W, 3)`` uint8 sRGB.
        mode: IRNet input mode: ``rgb+pseudo_nir`` (prepared RGB) or ``chroma+pseudo_nir``
            (its :func:`chromaticity`).

    Returns:
        ``(3, H, W)`` float32.
    """
    x = prepare_rgb(rgb)
    if mode == "chroma+pseudo_nir":
        return chromaticity(x)
    if mode == "rgb+pseudo_nir":
        return x
    raise NidarError(f"input mode {mode!r} has no colour channels before the pseudo-NIR")


def _check_rgb(rgb: np.ndarray) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8:
        raise NidarError(
            f"RGB image must be a uint8 numpy array, got {getattr(rgb, 'dtype', type(rgb))}"
        )
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(f"RGB image must be (H, W, 3), got shape {rgb.shape}")
