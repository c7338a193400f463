"""Image preparation shared by training and inference.

Camera frames arrive as 8-bit sRGB; the NIR target is linear band radiance. Both are brought
to a common, exposure-free scale before they reach a network:

1. sRGB is decoded to linear RGB with the IEC 61966-2-1 transfer function
   (:func:`nidar_mi.io.images.srgb_to_linear`, as a 256-entry table on the device), so that the
   spectral translation network combines linear radiances, as the cross-spectral image model
   ``NIR ~ sum_c w_c * RGB_c`` assumes.
2. Each image is multiplied by ``target_mean / (mean + eps)`` and clipped to
   ``[0, clamp_max]``: the per-image exposure normalisation of cs-stereo (Zhi et al., CVPR
   2018), which maps an unknown camera exposure to a mean of 0.5. The absolute scale of the
   NIR band is not recoverable from an 8-bit sRGB image, so the networks work in this
   normalised domain.

The steps run in torch on the device of the networks (:func:`prepare_rgb_tensor`); the NumPy
entry points (:func:`prepare_rgb`, :func:`prepare_nir`, :func:`colour_input`), used by the
training data, call the same functions on the CPU.
"""

from __future__ import annotations

import numpy as np
import torch

from ..errors import NidarError

__all__ = [
    "EXPOSURE_TARGET_MEAN",
    "EXPOSURE_CLAMP_MAX",
    "srgb8_to_linear",
    "srgb8_mean",
    "exposure_ratio",
    "normalize_exposure",
    "prepare_rgb",
    "prepare_rgb_tensor",
    "prepare_nir",
    "chromaticity",
    "colour_input",
    "colour_from_prepared",
]

#: Mean value an image has after exposure normalisation.
EXPOSURE_TARGET_MEAN = 0.5
#: Upper clip after exposure normalisation (cs-stereo's ``clamp_value``).
EXPOSURE_CLAMP_MAX = 5.0
_EPS = 1e-3
#: Added to the channel sum of :func:`chromaticity` (prepared RGB has mean 0.5 per channel).
CHROMA_EPS = 1e-2

_LUTS: dict[torch.device, torch.Tensor] = {}


def _srgb8_lut(device: torch.device) -> torch.Tensor:
    """(256,) float32 linear value of each 8-bit sRGB code on ``device`` (built once per device
    by :func:`nidar_mi.io.images.srgb_to_linear`, the one owner of the transfer function)."""
    lut = _LUTS.get(device)
    if lut is None:
        from ..io.images import srgb_to_linear

        codes = np.arange(256, dtype=np.float32) / np.float32(255.0)
        lut = torch.from_numpy(srgb_to_linear(codes).astype(np.float32)).to(device)
        _LUTS[device] = lut
    return lut


def srgb8_to_linear(rgb: torch.Tensor) -> torch.Tensor:
    """Decode 8-bit sRGB (IEC 61966-2-1) on the tensor's device: a 256-entry table look-up.

    Args:
        rgb: uint8 tensor of any shape and layout.

    Returns:
        Contiguous float32 tensor of the same shape and device, linear values in [0, 1]; equal
        to ``srgb_to_linear(rgb.astype(float32) / 255)``.
    """
    return _look_up(_srgb8_lut(rgb.device), rgb)


def _look_up(table: torch.Tensor, rgb: torch.Tensor) -> torch.Tensor:
    """``table[rgb]``: a (256,) table indexed by uint8 codes of any shape and layout, as a
    contiguous tensor of their shape on their device."""
    codes = rgb.to(torch.int32, memory_format=torch.contiguous_format)
    return table.index_select(0, codes.view(-1)).view(codes.shape)


def srgb8_mean(rgb: torch.Tensor) -> torch.Tensor:
    """0-d float64 tensor: the mean linear value of 8-bit sRGB codes (:func:`srgb8_to_linear`),
    from their histogram (exact products, 256 terms summed), on the tensor's device."""
    counts = torch.bincount(rgb.reshape(-1), minlength=256).to(torch.float64)
    return (counts * _srgb8_lut(rgb.device).to(torch.float64)).sum() / rgb.numel()


def exposure_ratio(mean: torch.Tensor, target_mean: float = EXPOSURE_TARGET_MEAN) -> torch.Tensor:
    """0-d float32 tensor ``target_mean / (mean + 1e-3)`` (in float32, as the images), from an
    image's 0-d mean, on its device (no host synchronisation)."""
    mean = mean.to(torch.float32)
    one = torch.ones((), dtype=torch.float32, device=mean.device)
    return (one * target_mean) / (mean + one * _EPS)


def _normalize(
    image: torch.Tensor, mean: torch.Tensor, target_mean: float, clamp_max: float
) -> torch.Tensor:
    """``clip(image * exposure_ratio(mean), 0, clamp_max)`` in float32 on the image's device."""
    image = image.to(torch.float32)
    return (image * exposure_ratio(mean, target_mean)).clamp_(0.0, clamp_max)


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
    t = _from_numpy(image)
    return _normalize(t, t.mean(dtype=torch.float64), target_mean, clamp_max).numpy()


def prepare_rgb_tensor(rgb: np.ndarray | torch.Tensor, device=None) -> torch.Tensor:
    """Network input from a camera image, computed on ``device``: linear, exposure-normalised,
    channels first.

    The 8-bit image goes to the device as it is (one upload of H·W·3 bytes); decoding and
    normalisation run there.

    Args:
        rgb: ``(H, W, 3)`` uint8 sRGB image, a NumPy array or a tensor (on any device).
        device: torch device of the result; None: the tensor's own (the CPU for an array).

    Returns:
        ``(3, H, W)`` float32 linear RGB with mean ~0.5, in ``[0, 5]``.
    """
    if not isinstance(rgb, torch.Tensor):
        _check_rgb(rgb)
        rgb = _from_numpy(rgb)
    elif rgb.dtype != torch.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(
            f"RGB image must be an (H, W, 3) uint8 tensor, got {rgb.dtype} {rgb.shape}"
        )
    rgb = rgb.to(device) if device is not None else rgb
    # decoding, scaling and clipping act on each code alone: applied to the 256-entry table,
    # then one look-up per pixel (the same values as on the decoded image, in one pass)
    table = _normalize(
        _srgb8_lut(rgb.device), srgb8_mean(rgb), EXPOSURE_TARGET_MEAN, EXPOSURE_CLAMP_MAX
    )
    return _look_up(table, rgb.permute(2, 0, 1))


def prepare_rgb(rgb: np.ndarray) -> np.ndarray:
    """:func:`prepare_rgb_tensor` as a NumPy array (on the CPU).

    Args:
        rgb: ``(H, W, 3)`` uint8 sRGB image.

    Returns:
        ``(3, H, W)`` float32 linear RGB with mean ~0.5, in ``[0, 5]``.
    """
    return prepare_rgb_tensor(rgb).numpy()


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


def chromaticity(x: np.ndarray | torch.Tensor) -> np.ndarray | torch.Tensor:
    """Shading-free colour of prepared RGB: ``x / (sum of channels + CHROMA_EPS)``.

    Args:
        x: ``(3, H, W)`` prepared RGB (:func:`prepare_rgb`), an array or a tensor.

    Returns:
        ``(3, H, W)`` float32 of the input's kind (and device) in ``[0, 1]``: each pixel's share
        of red, green and blue, the same under any brightness of its light (a black pixel gives 0).
    """
    if isinstance(x, np.ndarray):
        return chromaticity(_from_numpy(x)).numpy()
    x = x.to(torch.float32)
    return x / (x.sum(0, keepdim=True) + CHROMA_EPS)


def colour_from_prepared(x: torch.Tensor, mode: str) -> torch.Tensor:
    """The colour channels IRNet receives before its pseudo-NIR channel, from prepared RGB.

    Args:
        x: ``(3, H, W)`` prepared RGB (:func:`prepare_rgb_tensor`).
        mode: IRNet input mode: ``rgb+pseudo_nir`` (``x``) or ``chroma+pseudo_nir``
            (its :func:`chromaticity`).

    Returns:
        ``(3, H, W)`` float32 on ``x``'s device.
    """
    if mode == "chroma+pseudo_nir":
        return chromaticity(x)
    if mode == "rgb+pseudo_nir":
        return x
    raise NidarError(f"input mode {mode!r} has no colour channels before the pseudo-NIR")


def colour_input(rgb: np.ndarray, mode: str) -> np.ndarray:
    """:func:`colour_from_prepared` of an 8-bit image, as a NumPy array.

    Args:
        rgb: ``(H, W, 3)`` uint8 sRGB.
        mode: IRNet input mode (:func:`colour_from_prepared`).

    Returns:
        ``(3, H, W)`` float32.
    """
    return colour_from_prepared(prepare_rgb_tensor(rgb), mode).numpy()


def _from_numpy(a: np.ndarray) -> torch.Tensor:
    """A CPU tensor sharing ``a``'s memory, or of a contiguous copy when ``a`` is read-only or
    strided (torch does not take read-only arrays)."""
    if not (a.flags.writeable and a.flags.c_contiguous):
        a = np.array(a, order="C")
    return torch.from_numpy(a)


def _check_rgb(rgb: np.ndarray) -> None:
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8:
        raise NidarError(
            f"RGB image must be a uint8 numpy array, got {getattr(rgb, 'dtype', type(rgb))}"
        )
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise NidarError(f"RGB image must be (H, W, 3), got shape {rgb.shape}")
