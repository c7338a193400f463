"""Convolutional intensity heads of the IRNet ablation ("3Conv", "4Conv").

The paper's Conv head is a stack of 3x3 convolutions with BatchNorm and ELU; "3Conv" and
"4Conv" are 3- and 4-layer stacks. A 1x1 convolution maps the last layer to the output.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["ConvHead"]


class ConvHead(nn.Module):
    """``layers`` x (3x3 conv, BatchNorm, ELU), then a 1x1 convolution.

    Args:
        in_channels: input channels.
        out_channels: output channels.
        width: channels of the hidden layers.
        layers: number of 3x3 layers (3 or 4 in the paper).

    Maps ``(B, in_channels, H, W)`` to ``(B, out_channels, H, W)``.
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 16, layers: int = 3):
        super().__init__()
        if layers < 1:
            raise ValueError(f"layers must be >= 1, got {layers}")
        body: list[nn.Module] = []
        for k in range(layers):
            body += [
                nn.Conv2d(in_channels if k == 0 else width, width, 3, padding=1, bias=False),
                nn.BatchNorm2d(width),
                nn.ELU(inplace=True),
            ]
        self.body = nn.Sequential(*body)
        self.head = nn.Conv2d(width, out_channels, 1)

    @property
    def stride(self) -> int:
        """Any input size works."""
        return 1

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.body(x))
