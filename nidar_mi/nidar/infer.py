"""Inference of the trained NIDAR networks on whole camera images.

Images of any size are padded on the bottom and right (edge replication) to a multiple of the
networks' stride, run in eval mode without gradients, and cropped back.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import NidarError
from .irnet import IRNet
from .preprocess import prepare_rgb
from .stn import STN

__all__ = ["pad_to_multiple", "pseudo_nir", "predict"]


def pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """Replicate-pad ``(B, C, H, W)`` on the bottom/right so that ``H, W`` divide ``multiple``."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    return F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x


def _device(module: torch.nn.Module) -> torch.device:
    return next(module.parameters()).device


@torch.no_grad()
def pseudo_nir(stn: STN, rgb: np.ndarray) -> np.ndarray:
    """Pseudo-NIR image of an 8-bit sRGB camera image.

    Args:
        stn: trained STN.
        rgb: ``(H, W, 3)`` uint8 sRGB.

    Returns:
        ``(H, W)`` float32 pseudo-NIR in the exposure-normalised domain (mean ~0.5).
    """
    was_training = stn.training
    stn.eval()
    try:
        x = torch.from_numpy(prepare_rgb(rgb))[None].to(_device(stn))
        h, w = x.shape[-2:]
        out = stn(pad_to_multiple(x, stn.stride))[..., :h, :w]
    finally:
        stn.train(was_training)
    return out[0, 0].float().cpu().numpy()


@torch.no_grad()
def predict(stn: STN | None, irnet: IRNet, rgb: np.ndarray) -> dict[str, np.ndarray]:
    """Run NIDAR's learned stages on one camera image.

    Args:
        stn: trained STN; may be None when ``irnet`` takes RGB input.
        irnet: trained IRNet.
        rgb: ``(H, W, 3)`` uint8 sRGB.

    Returns:
        ``(H, W)`` float32 arrays: ``pseudo_nir`` (only when ``stn`` is given), ``R``
        (reflectance-related, in (0, 1)), ``S`` (shading) and ``I_hat`` (dense intensity in
        units of the training data's ``intensity_scale``).
    """
    if irnet.in_channels == 1 and stn is None:
        raise NidarError("this IRNet takes pseudo-NIR input: an STN is required")
    result: dict[str, np.ndarray] = {}
    if stn is not None:
        result["pseudo_nir"] = pseudo_nir(stn, rgb)
    if irnet.in_channels == 1:
        x = torch.from_numpy(result["pseudo_nir"])[None, None]
    else:
        x = torch.from_numpy(prepare_rgb(rgb))[None]
    was_training = irnet.training
    irnet.eval()
    try:
        h, w = x.shape[-2:]
        out = irnet(pad_to_multiple(x.to(_device(irnet)), irnet.stride))
    finally:
        irnet.train(was_training)
    for key in ("R", "S", "I_hat"):
        result[key] = out[key][0, 0, :h, :w].float().cpu().numpy()
    return result
