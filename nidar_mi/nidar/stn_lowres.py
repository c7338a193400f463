"""Pseudo-NIR network of the shipped model: per-pixel colour weights from a low-resolution UNet.

RGB -> pseudo-NIR as a spatially varying linear map of the colour channels,

    pseudo_nir(p) = w_r(p) · R(p) + w_g(p) · G(p) + w_b(p) · B(p) + b(p),

where the four coefficient maps come from a small UNet (:class:`~nidar_mi.nidar.unet.UNet`) run
on the image average-pooled by ``down`` and are resized bilinearly to the full size. The
colours carry the edges at full resolution; the network only decides, from context, how to mix
them (vegetation, sky and paints are bright or dark in NIR in ways no single colour map
captures). Full-resolution work is one bilinear resize and a 3-term product, which is what makes
it fast on a CPU (docs/BENCHMARKS.md).

It is the cs-stereo STN's idea (per-pixel channel weights, :mod:`nidar_mi.nidar.stn`) with an
offset, context at reduced resolution, and supervision by real, pixel-aligned RGB/NIR photos
(:mod:`nidar_mi.nidar.photo_data`, :func:`nidar_mi.nidar.losses.photo_stn_loss`). Inputs are
linear, exposure-normalised RGB (:func:`nidar_mi.nidar.preprocess.prepare_rgb`); the output is
in the same domain (a NIR image of mean ~0.5 up to an unknown gain and offset).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .unet import UNet

__all__ = ["LowResSTN"]


class LowResSTN(nn.Module):
    """Context UNet at ``1/down`` resolution -> per-pixel RGB weights and an offset.

    Args:
        width: base channel count of the UNet.
        depth: down-sampling steps of the UNet.
        down: average-pooling factor before the UNet (1: full resolution).

    ``forward`` maps ``(B, 3, H, W)`` (sides multiples of :attr:`stride`) to ``(B, 1, H, W)``.
    An untrained network averages the three channels (head bias 1/3, 1/3, 1/3, 0).
    """

    def __init__(self, width: int = 8, depth: int = 3, down: int = 2) -> None:
        super().__init__()
        if down < 1:
            raise ValueError(f"down must be >= 1, got {down}")
        self.down = int(down)
        self.unet = UNet(3, 4, width, depth)
        with torch.no_grad():
            self.unet.head.bias.copy_(torch.tensor([1 / 3, 1 / 3, 1 / 3, 0.0]))

    @property
    def stride(self) -> int:
        """Input sides must be multiples of this."""
        return self.down * self.unet.stride

    def coefficients(self, rgb: torch.Tensor) -> torch.Tensor:
        """``(B, 4, H / down, W / down)`` weights of R, G, B and the offset.

        Args:
            rgb: ``(B, 3, H, W)`` linear, exposure-normalised RGB, sides multiples of
                :attr:`stride`.
        """
        if rgb.ndim != 4 or rgb.shape[1] != 3:
            raise ValueError(f"rgb must be (B, 3, H, W), got {tuple(rgb.shape)}")
        small = F.avg_pool2d(rgb, self.down) if self.down > 1 else rgb
        return self.unet(small)

    @staticmethod
    def apply(rgb: torch.Tensor, coefficients: torch.Tensor) -> torch.Tensor:
        """``Σ_c w_c · rgb_c + b`` with the coefficients resized bilinearly to ``rgb``'s size.

        Args:
            rgb: ``(B, 3, H, W)``.
            coefficients: ``(B, 4, h, w)``.

        Returns:
            ``(B, 1, H, W)``.
        """
        size = tuple(rgb.shape[-2:])
        if tuple(coefficients.shape[-2:]) != size:
            coefficients = F.interpolate(
                coefficients, size=size, mode="bilinear", align_corners=False
            )
        r, g, b = rgb.unbind(1)
        w_r, w_g, w_b, offset = coefficients.unbind(1)
        # the channel sum in its order, without a (B, 3, H, W) product (2x faster on a CPU)
        return (w_r * r + w_g * g + w_b * b + offset)[:, None]

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        """Full-resolution pseudo-NIR ``(B, 1, H, W)``."""
        return self.apply(rgb, self.coefficients(rgb))
