"""Inference of the trained NIDAR networks on whole camera images.

Images of any size are padded on the bottom and right (edge replication) to a multiple of the
networks' stride, run in eval mode without gradients, and cropped back. Networks prepared with
:func:`nidar_mi.nidar.fold.prepare_for_inference` (channels-last parameters) get channels-last
inputs.

**Reduced-resolution inference** (``scale < 1``): the image is resized (area averaging) to
``round(scale · H) x round(scale · W)`` before a network sees it.

* STN: the per-pixel channel weights (and offset) are predicted at the reduced size, resized bilinearly to the
  full size and combined with the full-resolution RGB, so the pseudo-NIR keeps the image's own
  detail (the weights vary slowly; the colours carry the edges).
* IRNet: R, S and Î are predicted at the reduced size and resized bilinearly to the full size.

The outputs always have the input's size.

**JPEG blocks in the pseudo-NIR image.** The STN mixes the colour channels with weights of
opposite sign (e.g. +6 G and -6 B on vegetation), so it amplifies colour differences, and with
them a JPEG's chroma blocks (8 x 8 DCT blocks on chroma stored at half resolution: 16 px), most
visibly in dark areas where the exposure normalisation lifts them. The weight maps themselves are
smooth (bilinear, ``align_corners=False``; their own blockiness is ~1.0). The pseudo-NIR image
(:func:`pseudo_nir_linear`: the ``pseudo_nir`` command, the photo evaluation) therefore mixes the
weights with the image's per-pixel channel mean and its colour differences from that mean low-
passed by a Gaussian of :data:`CHROMA_SIGMA_PX` (a camera's chroma carries no finer detail); on
the held-out RGB/NIR photos this lowers the 16-px blockiness in dark areas from 1.35 to 1.15
(the NIR photos: 1.09) and raises Pearson r from 0.8096 to 0.8104. :func:`pseudo_nir` and
:func:`predict`, whose pseudo-NIR feeds IRNet, keep the input the IRNet was trained on.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import NidarError
from .irnet import IRNet
from .preprocess import (
    EXPOSURE_TARGET_MEAN,
    colour_from_prepared,
    prepare_rgb_tensor,
    srgb8_mean,
)
from .stn import STN
from .stn_lowres import LowResSTN

__all__ = [
    "CHROMA_SIGMA_PX",
    "IRNET_MAPS",
    "OUTPUTS",
    "pad_to_multiple",
    "smooth_chroma",
    "predict",
    "pseudo_nir",
    "pseudo_nir_linear",
    "reduced_size",
    "run_irnet",
]


def pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """Replicate-pad ``(B, C, H, W)`` on the bottom/right so that ``H, W`` divide ``multiple``."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    return F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x


def reduced_size(h: int, w: int, scale: float) -> tuple[int, int]:
    """``(round(scale · h), round(scale · w))``, at least 1 x 1.

    Raises:
        NidarError: ``scale`` not in (0, 1].
    """
    if not 0.0 < float(scale) <= 1.0:
        raise NidarError(f"inference scale must lie in (0, 1], got {scale}")
    return max(1, round(scale * h)), max(1, round(scale * w))


#: The maps IRNet gives.
IRNET_MAPS = ("R", "S", "I_hat")
#: The maps :func:`predict` can give.
OUTPUTS = ("pseudo_nir", *IRNET_MAPS)

#: Standard deviation (px) of the Gaussian low-pass on the colour differences of the pseudo-NIR
#: image (module docstring).
CHROMA_SIGMA_PX = 2.0


def smooth_chroma(x: torch.Tensor, sigma: float) -> torch.Tensor:
    """``(B, C, H, W)`` with each pixel's channel mean kept and the channels' differences from
    it low-passed by a Gaussian of ``sigma`` px (edges replicated); ``sigma <= 0``: ``x``."""
    if sigma <= 0:
        return x
    mean = x.mean(1, keepdim=True)
    r = max(1, int(3.0 * sigma + 0.5))
    t = torch.arange(-r, r + 1, dtype=x.dtype, device=x.device)
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    k = k / k.sum()
    c = x.shape[1]
    d = F.pad(x - mean, (r, r, r, r), mode="replicate")
    d = F.conv2d(d, k.view(1, 1, 1, -1).repeat(c, 1, 1, 1), groups=c)
    d = F.conv2d(d, k.view(1, 1, -1, 1).repeat(c, 1, 1, 1), groups=c)
    return mean + d


def _device(module: torch.nn.Module) -> torch.device:
    return next(module.parameters()).device


def _is_channels_last(module: torch.nn.Module) -> bool:
    for p in module.parameters():
        if p.ndim == 4:
            return p.is_contiguous(memory_format=torch.channels_last) and not p.is_contiguous()
    return False


def _run(net: torch.nn.Module, x: torch.Tensor):
    """``net`` on ``(B, C, H, W)`` padded to its stride, in eval mode (the mode is restored)."""
    was_training = net.training
    net.eval()
    try:
        x = pad_to_multiple(x.to(_device(net)), net.stride)
        if _is_channels_last(net):
            x = x.contiguous(memory_format=torch.channels_last)
        return net(x)
    finally:
        net.train(was_training)


def _resize(x: torch.Tensor, size: tuple[int, int], mode: str) -> torch.Tensor:
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    if mode == "area":
        return F.interpolate(x, size=size, mode="area")
    return F.interpolate(x, size=size, mode="bilinear", align_corners=False)


def _stn_forward(
    stn: STN,
    x: torch.Tensor,
    scale: float,
    chroma_sigma: float = 0.0,
    small: torch.Tensor | None = None,
) -> torch.Tensor:
    """Full-size ``(1, 1, H, W)`` pseudo-NIR of prepared RGB ``x`` (``(1, 3, H, W)``); the
    weights are applied to ``x`` with its colour differences low-passed by ``chroma_sigma`` px
    (:func:`smooth_chroma`; 0: ``x`` as it is). ``small``: ``x`` already area-resized to the
    reduced size of ``scale`` (computed here when None)."""
    h, w = x.shape[-2:]
    if scale == 1.0 and chroma_sigma <= 0:
        return _run(stn, x)[..., :h, :w]
    if small is None:
        small = _resize(x, reduced_size(h, w, scale), "area")
    was_training = stn.training
    stn.eval()
    try:
        xs = pad_to_multiple(small.to(_device(stn)), stn.stride)
        if _is_channels_last(stn):
            xs = xs.contiguous(memory_format=torch.channels_last)
        if isinstance(stn, LowResSTN):  # weights and offset at 1/down of the reduced size
            coef = stn.coefficients(xs)
            rows = -(-small.shape[-2] // stn.down)
            cols = -(-small.shape[-1] // stn.down)
            # resized channels-first: each weight map contiguous (2x faster than channels-last
            # on a CPU; the same values to float32 rounding, docs/BENCHMARKS.md)
            coef = _resize(coef[..., :rows, :cols].contiguous(), (h, w), "bilinear")
            return LowResSTN.apply(smooth_chroma(x.to(coef.device), chroma_sigma), coef)
        weights = stn.channel_weights(xs)[0][..., : small.shape[-2], : small.shape[-1]]
    finally:
        stn.train(was_training)
    weights = _resize(weights, (h, w), "bilinear")
    return (smooth_chroma(x.to(weights.device), chroma_sigma) * weights).sum(1, keepdim=True)


@torch.no_grad()
def pseudo_nir(
    stn: STN, rgb: np.ndarray | torch.Tensor, *, scale: float = 1.0, as_tensors: bool = False
) -> np.ndarray | torch.Tensor:
    """Pseudo-NIR image of an 8-bit sRGB camera image, in the network domain.

    Args:
        stn: trained STN.
        rgb: ``(H, W, 3)`` uint8 sRGB, a NumPy array or a tensor.
        scale: inference resolution relative to the image, in (0, 1] (module docstring).
        as_tensors: return a tensor on the STN's device instead of a NumPy array.

    Returns:
        ``(H, W)`` float32 pseudo-NIR in the exposure-normalised domain (mean ~0.5).
    """
    p = _pseudo_nir(stn, rgb, float(scale), 0.0)
    return p if as_tensors else p.cpu().numpy()


@torch.no_grad()
def _pseudo_nir(stn: STN, rgb, scale: float, chroma_sigma: float) -> torch.Tensor:
    """``(H, W)`` float32 pseudo-NIR on the STN's device."""
    x = prepare_rgb_tensor(rgb, _device(stn))[None]
    return _stn_forward(stn, x, scale, chroma_sigma)[0, 0].float()


def pseudo_nir_linear(stn: STN, rgb: np.ndarray, *, scale: float = 1.0) -> np.ndarray:
    """Pseudo-NIR at the input image's own exposure: linear, comparable with a NIR camera.

    The network works on exposure-normalised linear RGB (mean 0.5,
    :mod:`nidar_mi.nidar.preprocess`); the normalising factor is undone here, so a grey surface
    the camera records at linear value ``v`` in every channel gets pseudo-NIR ``≈ v · Σ w_c``.
    The colour differences are low-passed first (:data:`CHROMA_SIGMA_PX`, module docstring), so
    a JPEG's chroma blocks do not show.

    Args:
        stn: trained STN.
        rgb: ``(H, W, 3)`` uint8 sRGB.
        scale: inference resolution relative to the image, in (0, 1].

    Returns:
        ``(H, W)`` float32, linear, >= 0.
    """
    p = _pseudo_nir(stn, rgb, float(scale), CHROMA_SIGMA_PX).cpu().numpy()
    mean = float(srgb8_mean(torch.tensor(np.asarray(rgb))))
    ratio = EXPOSURE_TARGET_MEAN / (mean + 1e-3)  # the factor prepare_rgb applied
    return np.maximum(p / np.float32(ratio), 0.0).astype(np.float32)


def _host(maps: dict[str, torch.Tensor]) -> dict[str, np.ndarray]:
    """Tensors as float32 NumPy arrays on the host."""
    return {key: v.float().cpu().numpy() for key, v in maps.items()}


@torch.no_grad()
def run_irnet(
    irnet: IRNet,
    x: torch.Tensor,
    *,
    scale: float = 1.0,
    as_tensors: bool = False,
    outputs: tuple[str, ...] = IRNET_MAPS,
) -> dict[str, np.ndarray] | dict[str, torch.Tensor]:
    """IRNet's maps of one prepared input.

    Args:
        irnet: trained IRNet.
        x: ``(1, C, H, W)`` float32 network input: pseudo-NIR (``C = 1``, the STN's domain),
            prepared RGB (``C = 3``, :func:`~nidar_mi.nidar.preprocess.prepare_rgb`) or both
            (``C = 4``: RGB, then pseudo-NIR).
        scale: inference resolution relative to the input, in (0, 1].
        as_tensors: return tensors on the network's device instead of NumPy arrays.
        outputs: the maps to return, any of :data:`IRNET_MAPS`.

    Returns:
        ``(H, W)`` float32 maps: ``R``, ``S`` and ``I_hat`` (those in ``outputs``).
    """
    h, w = x.shape[-2:]
    maps = _irnet_maps(irnet, _resize(x, reduced_size(h, w, float(scale)), "area"), (h, w), outputs)
    return maps if as_tensors else _host(maps)


def _irnet_maps(
    irnet: IRNet, small: torch.Tensor, size: tuple[int, int], outputs
) -> dict[str, torch.Tensor]:
    """IRNet on its reduced-size input ``small`` (``(1, C, h, w)``); the maps named in
    ``outputs`` resized bilinearly to ``size``, float32 ``(H, W)`` tensors on its device."""
    out = _run(irnet, small)
    h, w = small.shape[-2:]
    return {
        key: _resize(out[key][..., :h, :w], size, "bilinear")[0, 0].float()
        for key in IRNET_MAPS
        if key in outputs
    }


@torch.no_grad()
def predict(
    stn: STN | None,
    irnet: IRNet,
    rgb: np.ndarray | torch.Tensor,
    *,
    scale: float = 1.0,
    as_tensors: bool = False,
    outputs: tuple[str, ...] = OUTPUTS,
) -> dict[str, np.ndarray] | dict[str, torch.Tensor]:
    """Run NIDAR's learned stages on one camera image, on the networks' device.

    The 8-bit image goes to the device once; its preparation
    (:func:`~nidar_mi.nidar.preprocess.prepare_rgb_tensor`), both networks and the resizing run
    there. With ``as_tensors`` the maps stay there; else they come back once, as arrays. The
    image is area-resized to the inference size once: the STN's context and IRNet's colour
    channels both take it (area averaging acts on each channel alone, so this equals resizing
    IRNet's whole input); only the maps asked for are resized back to the full size.

    Args:
        stn: trained STN; may be None when ``irnet`` takes RGB input.
        irnet: trained IRNet.
        rgb: ``(H, W, 3)`` uint8 sRGB, a NumPy array or a tensor.
        scale: inference resolution relative to the image, in (0, 1] (module docstring).
        as_tensors: return ``(H, W)`` float32 tensors on the networks' device.
        outputs: the maps to return, any of :data:`OUTPUTS` (``pseudo_nir`` only with an STN).

    Returns:
        ``(H, W)`` float32 maps: ``pseudo_nir`` (only when ``stn`` is given), ``R``
        (reflectance-related, in (0, 1)), ``S`` (shading) and ``I_hat`` (dense intensity in
        units of the training data's ``intensity_scale``); those in ``outputs``.
    """
    unknown = [key for key in outputs if key not in OUTPUTS]
    if unknown:
        raise NidarError(f"unknown NIDAR map(s) {unknown}: choose from {', '.join(OUTPUTS)}")
    if irnet.in_channels in (1, 4) and stn is None:
        raise NidarError("this IRNet takes pseudo-NIR input: an STN is required")
    x_rgb = prepare_rgb_tensor(rgb, _device(irnet))[None]
    h, w = x_rgb.shape[-2:]
    size = reduced_size(h, w, float(scale))
    small_rgb = _resize(x_rgb, size, "area")
    result: dict[str, torch.Tensor] = {}
    small = small_rgb
    if stn is not None and (irnet.in_channels in (1, 4) or "pseudo_nir" in outputs):
        p = _stn_forward(stn, x_rgb, float(scale), small=small_rgb)
        if "pseudo_nir" in outputs:
            result["pseudo_nir"] = p[0, 0].float()
        if irnet.in_channels == 1:
            small = _resize(p, size, "area")
        elif irnet.in_channels == 4:
            if irnet.input_mode == "rgb+pseudo_nir":
                colour = small_rgb
            else:
                colour = _resize(
                    colour_from_prepared(x_rgb[0], irnet.input_mode)[None], size, "area"
                )
            small = torch.cat((colour.to(p.device), _resize(p, size, "area")), 1)
    if any(key in IRNET_MAPS for key in outputs):
        result |= _irnet_maps(irnet, small, (h, w), outputs)
    return result if as_tensors else _host(result)
