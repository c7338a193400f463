"""DeepLabV3 (Chen et al., 2017): a dilated residual encoder and Atrous Spatial Pyramid Pooling.

The encoder is a small ResNet (a stride-2 stem, then four stages of one basic residual block
with ``width, 2 width, 4 width, 8 width`` channels). Stages stride by 2 until the requested
output stride is reached; later stages keep the resolution and double their dilation
instead, as in DeepLabV3. ASPP runs a 1x1 convolution, three dilated 3x3 convolutions and an
image-level pooling branch in parallel, concatenates them and projects with a 1x1
convolution; a 3x3 convolution follows and the result is up-sampled bilinearly to the input
size (DeepLabV3 has no decoder). Differences from the paper's ResNet-101 model, chosen for
CPU-sized training: one block per stage, configurable width, no dropout, and no BatchNorm in
the image-pooling branch (a 1x1 map cannot be batch-normalised with a batch of one).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["ASPP", "DeepLabV3", "DilatedResNet"]


def _conv_bn_relu(in_ch: int, out_ch: int, k: int, stride: int = 1, dilation: int = 1):
    pad = dilation * (k // 2)
    return nn.Sequential(
        nn.Conv2d(in_ch, out_ch, k, stride=stride, padding=pad, dilation=dilation, bias=False),
        nn.BatchNorm2d(out_ch),
        nn.ReLU(inplace=True),
    )


class _BasicBlock(nn.Module):
    def __init__(self, in_ch: int, out_ch: int, stride: int, dilation: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(in_ch, out_ch, 3, stride, dilation, dilation, bias=False)
        self.bn1 = nn.BatchNorm2d(out_ch)
        self.conv2 = nn.Conv2d(out_ch, out_ch, 3, 1, dilation, dilation, bias=False)
        self.bn2 = nn.BatchNorm2d(out_ch)
        self.shortcut = (
            nn.Sequential(nn.Conv2d(in_ch, out_ch, 1, stride, bias=False), nn.BatchNorm2d(out_ch))
            if stride != 1 or in_ch != out_ch
            else nn.Identity()
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        return F.relu(y + self.shortcut(x))


class DilatedResNet(nn.Module):
    """ResNet encoder with a bounded output stride.

    Args:
        in_channels: input channels.
        width: channels of the stem and first stage; stage ``k`` has ``width * 2**k``.
        output_stride: ratio of input to output resolution (2, 4, 8, 16 or 32).

    Maps ``(B, in_channels, H, W)`` to ``(B, 8 width, ceil(H / os), ceil(W / os))``.
    """

    def __init__(self, in_channels: int, width: int = 16, output_stride: int = 8) -> None:
        super().__init__()
        if output_stride not in (2, 4, 8, 16, 32):
            raise ValueError(f"output_stride must be 2, 4, 8, 16 or 32, got {output_stride}")
        self.stem = _conv_bn_relu(in_channels, width, 3, stride=2)
        stride, dilation, in_ch = 2, 1, width
        stages = []
        for k in range(4):
            out_ch = width * 2**k
            if k == 0:
                step = 1
            elif stride < output_stride:
                step, stride = 2, stride * 2
            else:
                step, dilation = 1, dilation * 2
            stages.append(_BasicBlock(in_ch, out_ch, step, dilation))
            in_ch = out_ch
        self.stages = nn.Sequential(*stages)
        self.out_channels = in_ch
        self.output_stride = output_stride

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.stages(self.stem(x))


class _ImagePooling(nn.Module):
    def __init__(self, in_ch: int, out_ch: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_ch, out_ch, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.conv(F.adaptive_avg_pool2d(x, 1)))
        return y.expand(-1, -1, *x.shape[-2:])


class ASPP(nn.Module):
    """Atrous Spatial Pyramid Pooling.

    Args:
        in_channels: input channels.
        out_channels: channels of every branch and of the output.
        rates: dilation rates of the 3x3 branches.

    Maps ``(B, in_channels, h, w)`` to ``(B, out_channels, h, w)``.
    """

    def __init__(self, in_channels: int, out_channels: int, rates=(6, 12, 18)) -> None:
        super().__init__()
        branches = [_conv_bn_relu(in_channels, out_channels, 1)]
        branches += [_conv_bn_relu(in_channels, out_channels, 3, dilation=r) for r in rates]
        branches.append(_ImagePooling(in_channels, out_channels))
        self.branches = nn.ModuleList(branches)
        self.project = _conv_bn_relu(len(branches) * out_channels, out_channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.project(torch.cat([b(x) for b in self.branches], 1))


class DeepLabV3(nn.Module):
    """DeepLabV3: dilated ResNet, ASPP, 3x3 convolution, bilinear up-sampling, 1x1 output.

    Args:
        in_channels: input channels.
        out_channels: output channels.
        width: encoder base width; ASPP uses ``4 * width`` channels and the up-sampled
            features ``width``.
        output_stride: encoder output stride.
        rates: ASPP dilation rates.

    Example:
        >>> DeepLabV3(1, 1, width=4, output_stride=4, rates=(1, 2))(torch.rand(2, 1, 16, 16)).shape
        torch.Size([2, 1, 16, 16])
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        width: int = 16,
        output_stride: int = 8,
        rates=(6, 12, 18),
    ) -> None:
        super().__init__()
        self.encoder = DilatedResNet(in_channels, width, output_stride)
        self.aspp = ASPP(self.encoder.out_channels, 4 * width, tuple(rates))
        self.refine = _conv_bn_relu(4 * width, width, 3)
        self.head = nn.Conv2d(width, out_channels, 1)

    @property
    def stride(self) -> int:
        """Input sides should be multiples of this (others work, but lose alignment)."""
        return self.encoder.output_stride

    @property
    def feature_channels(self) -> int:
        """Channels of :meth:`features`."""
        return self.head.in_channels

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Up-sampled features ``(B, width, H, W)`` of ``(B, in_channels, H, W)``."""
        y = self.refine(self.aspp(self.encoder(x)))
        return F.interpolate(y, size=x.shape[-2:], mode="bilinear", align_corners=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in_channels, H, W)`` -> ``(B, out_channels, H, W)``."""
        return self.head(self.features(x))
