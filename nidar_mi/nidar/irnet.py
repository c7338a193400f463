"""IRNet: intrinsic decomposition of pseudo-NIR and dense LiDAR-intensity prediction.

A decomposition backbone (UNet or DeepLabV3) maps the input image to reflectance ``R`` and
shading ``S`` with ``I_recon = R * S``; an intensity head predicts dense intensity ``I_hat``
from the backbone's full-resolution features concatenated with ``R`` and ``S`` (the
hierarchical structure of the paper). Variants are named ``backbone`` or ``backbone+head``
(:data:`nidar_mi.nidar.config.IRNET_VARIANTS`); a backbone alone predicts
``(R, S, I_hat)`` as three output channels. The paper's model is ``unet+deeplabv3``.

Output ranges: ``R = sigmoid(.)`` in ``(0, 1)``; ``S = softplus(.)`` and
``I_hat = softplus(.)`` non-negative. With ``in_channels = 3`` (the RGB-input diagnostic)
the image the decomposition explains is the Rec. 709 luminance of the input
(:data:`nidar_mi.io.images.REC709_LUMA`)
(:meth:`IRNet.intrinsic_target`), so that ``R`` stays single-channel and comparable. With
``in_channels = 4`` (linear RGB, then pseudo-NIR) it is the pseudo-NIR channel: the colour is
context that tells the reflectance, the pseudo-NIR the image that ``R * S`` explains.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..io.images import REC709_LUMA
from .aspp import DeepLabV3
from .config import IRNET_VARIANTS
from .heads import ConvHead
from .unet import UNet

__all__ = ["IRNet", "parse_variant"]


def parse_variant(name: str) -> tuple[str, str | None]:
    """Split a variant name into ``(backbone, head)``.

    Accepts the paper's spelling too (``"U-Net+DeepLabV3"``), case-insensitively.

    Returns:
        ``backbone`` in ``{"unet", "deeplabv3"}``; ``head`` in
        ``{None, "3conv", "4conv", "unet", "deeplabv3"}``.
    """
    key = name.strip().lower().replace("-", "").replace(" ", "")
    if key not in IRNET_VARIANTS:
        raise ValueError(f"unknown IRNet variant {name!r}; choose one of {IRNET_VARIANTS}")
    parts = key.split("+")
    return parts[0], (parts[1] if len(parts) > 1 else None)


class IRNet(nn.Module):
    """Intrinsic reflectance network.

    Args:
        variant: ablation variant, e.g. ``"unet+deeplabv3"``.
        in_channels: 1 (pseudo-NIR), 3 (linear RGB) or 4 (linear RGB and pseudo-NIR).
        width: base width of every sub-network.
        unet_depth: down-sampling steps of UNet parts.
        output_stride: output stride of DeepLabV3 parts.
        aspp_rates: ASPP dilation rates of DeepLabV3 parts.
        input_mode: what the channels hold (:data:`nidar_mi.nidar.config.INPUT_MODES`; None:
            ``pseudo_nir``, ``rgb`` or ``rgb+pseudo_nir`` by ``in_channels``); kept as
            :attr:`input_mode` for inference.

    ``forward`` maps ``(B, in_channels, H, W)`` (sides multiples of :attr:`stride`) to a dict
    of ``(B, 1, H, W)`` tensors ``R``, ``S``, ``I_hat``.
    """

    def __init__(
        self,
        variant: str = "unet+deeplabv3",
        in_channels: int = 1,
        width: int = 16,
        unet_depth: int = 4,
        output_stride: int = 8,
        aspp_rates=(6, 12, 18),
        input_mode: str | None = None,
    ) -> None:
        super().__init__()
        if in_channels not in (1, 3, 4):
            raise ValueError(f"in_channels must be 1, 3 or 4, got {in_channels}")
        self.variant = variant
        self.in_channels = in_channels
        default = {1: "pseudo_nir", 3: "rgb", 4: "rgb+pseudo_nir"}[in_channels]
        self.input_mode = input_mode or default
        backbone, head = parse_variant(variant)

        def network(kind: str, cin: int, cout: int) -> nn.Module:
            if kind == "unet":
                return UNet(cin, cout, width, unet_depth)
            if kind == "deeplabv3":
                return DeepLabV3(cin, cout, width, output_stride, aspp_rates)
            return ConvHead(cin, cout, width, layers=int(kind[0]))

        self.backbone = network(backbone, in_channels, 2 if head else 3)
        self.head = (
            network(head, self.backbone.feature_channels + 2, 1) if head is not None else None
        )
        self.register_buffer(
            "luma", torch.tensor(REC709_LUMA).reshape(1, 3, 1, 1), persistent=False
        )

    @property
    def stride(self) -> int:
        """Input sides must be multiples of this."""
        parts = [self.backbone] + ([self.head] if self.head is not None else [])
        return max(p.stride for p in parts)

    def intrinsic_target(self, x: torch.Tensor) -> torch.Tensor:
        """The image ``I`` that ``R * S`` explains: ``x`` itself, its luminance for RGB, its
        pseudo-NIR channel (the last) for RGB + pseudo-NIR.

        Args:
            x: ``(B, in_channels, H, W)`` network input.

        Returns:
            ``(B, 1, H, W)``.
        """
        if x.shape[1] == 1:
            return x
        if x.shape[1] == 4:
            return x[:, 3:4]
        return (x * self.luma.to(x.dtype)).sum(1, keepdim=True)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        if x.ndim != 4 or x.shape[1] != self.in_channels:
            raise ValueError(f"input must be (B, {self.in_channels}, H, W), got {tuple(x.shape)}")
        h, w = x.shape[-2:]
        if h % self.stride or w % self.stride:
            raise ValueError(f"image sides {h}x{w} must be multiples of {self.stride}")
        feats = self.backbone.features(x)
        out = self.backbone.head(feats)
        r = torch.sigmoid(out[:, 0:1])
        s = F.softplus(out[:, 1:2])
        if self.head is None:
            i_raw = out[:, 2:3]
        else:
            i_raw = self.head(torch.cat((feats, r, s), 1))
        return {"R": r, "S": s, "I_hat": F.softplus(i_raw)}
