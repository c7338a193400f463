"""UNet encoder-decoder (Ronneberger et al., MICCAI 2015), with BatchNorm.

Each level is two 3x3 convolution + BatchNorm + ReLU layers; the encoder halves the
resolution with 2x2 max pooling and doubles the channels, the decoder up-samples bilinearly,
concatenates the skip connection of the same level and applies a double convolution.
Convolutions are padded, so the output has the input's size.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["DoubleConv", "UNet"]


class DoubleConv(nn.Sequential):
    """Two (3x3 conv, BatchNorm, ReLU) layers: ``(B, in_ch, H, W)`` -> ``(B, out_ch, H, W)``."""

    def __init__(self, in_ch: int, out_ch: int) -> None:
        super().__init__(
            nn.Conv2d(in_ch, out_ch, 3, padding=1, bias=False),
            nn.BatchNorm2d(out_ch),
            nn.ReLU(inplace=True),
            nn.Conv2d(out_ch, out_ch, 3, padding=1, bias=False),
            nn.BatchNorm2d(out_ch),
            nn.ReLU(inplace=True),
        )


class UNet(nn.Module):
    """UNet.

    Args:
        in_channels: input channels.
        out_channels: output channels of the final 1x1 convolution.
        width: channels of the first level; level ``k`` has ``width * 2**k``.
        depth: number of down-sampling steps; input sides must be multiples of
            :attr:`stride` ``= 2**depth``.

    Example:
        >>> UNet(1, 2, width=4, depth=2)(torch.rand(1, 1, 16, 16)).shape
        torch.Size([1, 2, 16, 16])
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 16, depth: int = 4):
        super().__init__()
        if depth < 1:
            raise ValueError(f"depth must be >= 1, got {depth}")
        self.depth = depth
        ch = [width * 2**k for k in range(depth + 1)]
        self.down = nn.ModuleList(
            DoubleConv(in_channels if k == 0 else ch[k - 1], ch[k]) for k in range(depth + 1)
        )
        self.up = nn.ModuleList(DoubleConv(ch[k + 1] + ch[k], ch[k]) for k in range(depth))
        self.head = nn.Conv2d(ch[0], out_channels, 1)

    @property
    def stride(self) -> int:
        """Input sides must be multiples of this."""
        return 2**self.depth

    @property
    def feature_channels(self) -> int:
        """Channels of :meth:`features`."""
        return self.head.in_channels

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Last decoder features ``(B, width, H, W)`` of ``(B, in_channels, H, W)``."""
        h, w = x.shape[-2:]
        if h % self.stride or w % self.stride:
            raise ValueError(f"image sides {h}x{w} must be multiples of {self.stride}")
        skips = []
        for k, block in enumerate(self.down):
            x = block(x if k == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        x = skips.pop()
        for k in range(self.depth - 1, -1, -1):
            skip = skips.pop()
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = self.up[k](torch.cat((x, skip), 1))
        return x

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in_channels, H, W)`` -> ``(B, out_channels, H, W)``."""
        return self.head(self.features(x))
